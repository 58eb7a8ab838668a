"""spherevm.random: Philox4x32-10 known answers, the (seed, stream, timestep, id) construction,
determinism, independence, batching invariance and statistics of uniform and normal draws."""
import math

import numpy as np
import pytest
from scipy import stats

from spherevm import random as svr

from conftest import PHILOX_KAT as KAT


N_STAT = 500_000   # ids in the statistical tests; 2 draws each -> 1e6 draws


@pytest.mark.parametrize("rounds,ctr,key,expected", KAT)
def test_philox_known_answers(rounds, ctr, key, expected):
    out = svr.philox4x32(np.array(ctr, dtype=np.uint32), np.array(key, dtype=np.uint32), rounds=rounds)
    assert out.dtype == np.uint32
    assert out.tolist() == expected
    if rounds == 10:
        assert svr.philox4x32(ctr, key).tolist() == expected   # default rounds, Python int input


def test_philox_vectorised_and_broadcast():
    ctrs = np.array([k[1] for k in KAT if k[0] == 10], dtype=np.uint32)
    keys = np.array([k[2] for k in KAT if k[0] == 10], dtype=np.uint32)
    expected = np.array([k[3] for k in KAT if k[0] == 10], dtype=np.uint32)
    np.testing.assert_array_equal(svr.philox4x32(ctrs, keys), expected)
    # one key broadcast over a (2, 3) batch of counters
    batch = np.stack([ctrs, ctrs[::-1]])
    out = svr.philox4x32(batch, keys[2])
    assert out.shape == (2, 3, 4)
    np.testing.assert_array_equal(out[0, 2], expected[2])
    np.testing.assert_array_equal(out[1, 0], expected[2])
    # and one counter broadcast over a (2, 3) batch of keys
    out = svr.philox4x32(ctrs[1], np.stack([keys, keys[::-1]]))
    assert out.shape == (2, 3, 4)
    np.testing.assert_array_equal(out[0, 1], expected[1])
    np.testing.assert_array_equal(out[1, 1], expected[1])


def test_philox_rejects_bad_shapes_and_values():
    with pytest.raises(ValueError, match="counter"):
        svr.philox4x32(np.zeros(3, np.uint32), np.zeros(2, np.uint32))
    with pytest.raises(ValueError, match="key"):
        svr.philox4x32(np.zeros(4, np.uint32), np.zeros(3, np.uint32))
    with pytest.raises(ValueError, match="2\\*\\*32"):
        svr.philox4x32([0, 0, 0, 2**32], [0, 0])
    with pytest.raises(ValueError, match="2\\*\\*32"):
        svr.philox4x32([0, 0, 0, 0], [-1, 0])


def test_uniform_is_the_documented_construction():
    """uniform == uniform_from_words(Philox((id, t_lo, t_hi, block), (seed, stream))), by hand."""
    seed, stream, t, ids = 2024, svr.STREAM_ACTIVE, 2**40 + 7, np.array([0, 5, 2**32 - 1])
    u = svr.uniform(seed, stream, t, ids, count=5)
    for i, vid in enumerate(ids):
        for j in range(5):
            w = svr.philox4x32([int(vid), t & 0xFFFFFFFF, t >> 32, j // 2], [seed, stream])
            hi, lo = (int(w[0]), int(w[1])) if j % 2 == 0 else (int(w[2]), int(w[3]))
            n = (hi << 20) | (lo >> 12)
            assert u[i, j] == (2 * n + 1) * 2.0**-53   # exact, Python ints and floats
            assert u[i, j] == (n + 0.5) / 2**52


def test_uniform_from_words_extremes_are_exact():
    ext = svr.uniform_from_words(np.array([0, 0xFFFFFFFF, 0x80000000]), np.array([0, 0xFFFFFFFF, 0]))
    assert ext[0] == 2.0**-53
    assert ext[1] == 1.0 - 2.0**-53
    assert ext[2] == 0.5 + 2.0**-53
    assert 0.0 < ext[0] and ext[1] < 1.0


def test_normal_is_box_muller_of_the_uniforms():
    seed, stream, t, ids = 7, svr.STREAM_BROWNIAN, 123, np.arange(1000)
    u = svr.uniform(seed, stream, t, ids, count=6)
    z = svr.normal(seed, stream, t, ids, count=6)
    r = np.sqrt(-2.0 * np.log(u[:, 0::2]))
    th = svr.TWO_PI * u[:, 1::2]
    np.testing.assert_array_equal(z[:, 0::2], r * np.cos(th))
    np.testing.assert_array_equal(z[:, 1::2], r * np.sin(th))
    assert svr.TWO_PI == 2.0 * math.pi


@pytest.mark.parametrize("draw", [svr.uniform, svr.normal])
def test_shape_dtype_and_determinism(draw):
    ids = np.array([3, 1, 4, 1, 5, 9, 2, 6])
    a = draw(42, 0, 17, ids, count=3)
    b = draw(42, 0, 17, ids.copy(), count=3)
    assert a.shape == (8, 3) and a.dtype == np.float64
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(a[1], a[3])            # same id, same numbers
    assert draw(42, 0, 17, ids).shape == (8, 1)          # count defaults to 1
    assert draw(42, 0, 17, 5, count=2).shape == (1, 2)   # a scalar id is one id
    assert draw(42, 0, 17, np.array([], dtype=np.int64), count=2).shape == (0, 2)
    assert draw(42, 0, 17, [], count=2).shape == (0, 2)
    # many draws per id are allowed (up to 2**32), and the first ones do not change
    many = draw(42, 0, 17, ids[:2], count=101)
    assert many.shape == (2, 101)
    np.testing.assert_array_equal(many[:, :3], a[:2])
    for bad in (0, -1):
        with pytest.raises(ValueError, match="count"):
            draw(42, 0, 17, [], count=bad)


@pytest.mark.parametrize("draw", [svr.uniform, svr.normal])
def test_different_inputs_give_different_numbers(draw):
    ids = np.arange(1000)
    base = draw(1, 0, 10, ids, count=4)
    others = [draw(2, 0, 10, ids, count=4),             # seed
              draw(1, 1, 10, ids, count=4),             # stream
              draw(1, 0, 11, ids, count=4),             # timestep, low word
              draw(1, 0, 10 + 2**32, ids, count=4),     # timestep, high word
              draw(1, 0, 10, ids + 1000, count=4)]      # ids
    for other in others:
        assert not np.any(other == base)
    # ids and draws within a row are all distinct
    assert np.unique(base).size == base.size


@pytest.mark.parametrize("draw", [svr.uniform, svr.normal])
def test_independent_of_batching_and_count(draw):
    rng = np.random.default_rng(0)
    ids = rng.integers(0, 2**32, size=64, dtype=np.uint64)
    t = 2**33 + 99
    together = draw(9, 1, t, ids, count=5)
    one_by_one = np.concatenate([draw(9, 1, t, [i], count=5) for i in ids])
    np.testing.assert_array_equal(together, one_by_one)
    perm = rng.permutation(ids.size)
    np.testing.assert_array_equal(draw(9, 1, t, ids[perm], count=5), together[perm])
    # asking for more draws appends columns; the first ones do not change
    for count in (1, 2, 3, 4):
        np.testing.assert_array_equal(draw(9, 1, t, ids, count=count), together[:, :count])
    # id dtype does not matter
    np.testing.assert_array_equal(draw(9, 1, t, ids.astype(np.int64), count=5), together)
    np.testing.assert_array_equal(draw(9, 1, np.uint64(t), ids.astype(np.uint32), count=5), together)


def test_extreme_arguments():
    u = svr.uniform(2**32 - 1, 2**32 - 1, 2**64 - 1, [0, 2**32 - 1], count=3)
    z = svr.normal(2**32 - 1, 2**32 - 1, 2**64 - 1, [0, 2**32 - 1], count=3)
    assert np.all((u > 0) & (u < 1)) and np.all(np.isfinite(z))


@pytest.mark.parametrize("draw", [svr.uniform, svr.normal])
@pytest.mark.parametrize("kwargs,name", [
    (dict(seed=-1), "seed"), (dict(seed=2**32), "seed"), (dict(seed=1.5), "seed"),
    (dict(stream=-1), "stream"), (dict(stream=2**32), "stream"),
    (dict(timestep=-1), "timestep"), (dict(timestep=2**64), "timestep"),
    (dict(ids=[0, -1]), "ids"), (dict(ids=[2**32]), "ids"), (dict(ids=[0.5]), "ids"),
    (dict(ids=[[0, 1]]), "ids"),
    (dict(count=0), "count"), (dict(count=-2), "count"),
])
def test_bad_input_raises(draw, kwargs, name):
    args = dict(seed=1, stream=0, timestep=0, ids=[0, 1], count=1)
    args.update(kwargs)
    with pytest.raises(ValueError, match=name) as err:
        draw(**args)
    assert "[" in str(err.value) or "shape" in str(err.value)   # the message gives the allowed range


@pytest.fixture(scope="module")
def uniforms():
    return svr.uniform(20240601, svr.STREAM_BROWNIAN, 1000, np.arange(N_STAT), count=2).ravel()


@pytest.fixture(scope="module")
def normals():
    return svr.normal(20240601, svr.STREAM_ACTIVE, 1000, np.arange(N_STAT), count=2).ravel()


def test_uniform_statistics(uniforms):
    n = uniforms.size
    assert n == 1_000_000
    assert np.all(uniforms > 0.0) and np.all(uniforms < 1.0)
    # mean 1/2 (sd of a uniform: 1/sqrt(12)); variance 1/12 (sd of the sample variance:
    # sqrt((mu4 - sigma^4) / n) with mu4 = 1/80)
    assert abs(uniforms.mean() - 0.5) < 5 * math.sqrt(1 / 12 / n)
    assert abs(uniforms.var() - 1 / 12) < 5 * math.sqrt((1 / 80 - 1 / 144) / n)
    assert stats.kstest(uniforms, "uniform").pvalue > 1e-3
    # the two draws of a block are uncorrelated
    pair = uniforms.reshape(-1, 2)
    assert abs(np.corrcoef(pair[:, 0], pair[:, 1])[0, 1]) < 5 / math.sqrt(pair.shape[0])


def test_normal_statistics(normals):
    n = normals.size
    assert np.all(np.isfinite(normals))
    assert np.abs(normals).max() <= math.sqrt(-2 * math.log(2.0**-53)) + 1e-12
    assert abs(normals.mean()) < 5 / math.sqrt(n)
    assert abs(normals.var() - 1.0) < 5 * math.sqrt(2 / n)   # mu4 - sigma^4 = 2
    assert stats.kstest(normals, "norm").pvalue > 1e-3
    pair = normals.reshape(-1, 2)                             # cos and sin of one Box-Muller pair
    assert abs(np.corrcoef(pair[:, 0], pair[:, 1])[0, 1]) < 5 / math.sqrt(pair.shape[0])


def test_stream_numbers_are_distinct_and_match_the_cuda_header():
    import pathlib
    import re
    names = [n for n in svr.__all__ if n.startswith("STREAM_")]
    values = [getattr(svr, n) for n in names]
    assert len(set(values)) == len(values)
    header = (pathlib.Path(svr.__file__).parent / "random_philox.cuh").read_text()
    for name, value in zip(names, values):
        m = re.search(rf"#define SVM_{name} (\d+)u", header)
        assert m and int(m.group(1)) == value, name
    for name in ("M0", "M1", "W0", "W1"):
        m = re.search(rf"#define SVM_PHILOX_{name} 0x([0-9A-F]+)u", header)
        assert m and int(m.group(1), 16) == getattr(svr, f"PHILOX_{name}"), name
    assert float(re.search(r"#define SVM_TWO_PI ([0-9.]+)", header).group(1)) == svr.TWO_PI
