"""Cell shapes on the GPU (spherevm.constraints.kernels.cell_measures: one kernel, the vertex
model's own formulas) against analytic polygons, the conservation of the surface's area, and NumPy."""
import numpy as np
import pytest

import spherevm as svm
from spherevm import shapes
from spherevm.analysis import regular_polygon_perimeter

pytestmark = pytest.mark.gpu


def test_the_dodecahedron_on_the_gpu_has_its_regular_pentagons():
    R = 1.7
    gpu = svm.init.regular_tiling("dodecahedron", radius=R).to("gpu")
    area, perimeter = shapes.cell_shapes(gpu)
    assert isinstance(area, np.ndarray) and area.shape == (12,)
    assert np.abs(area - 4 * np.pi * R ** 2 / 12).max() <= 1e-13 * area.max()
    expected = regular_polygon_perimeter(5, 4 * np.pi * R ** 2 / 12, R)
    assert np.abs(perimeter - expected).max() <= 1e-13 * expected


@pytest.mark.parametrize("surface", ["sphere", "plane"])
def test_gpu_shapes_are_numpys_and_tile_the_surface(surface):
    tiling = svm.init.random_planar_tiling if surface == "plane" else svm.init.random_tiling
    cpu = svm.State.concatenate([tiling(n, seed=5 + n) for n in (32, 300, 90)])
    gpu = cpu.to("gpu")
    (a_cpu, p_cpu), (a_gpu, p_gpu) = shapes.cell_shapes(cpu), shapes.cell_shapes(gpu)
    assert np.abs(a_gpu - a_cpu).max() <= 1e-12 * np.abs(a_cpu).max()
    assert np.abs(p_gpu - p_cpu).max() <= 1e-12 * p_cpu.max()
    total = np.bincount(cpu.cell_replica_np(), weights=a_gpu)
    expected = cpu.constraint.total_area_np(cpu.radius if surface == "sphere" else cpu.box)
    assert np.abs(total - expected).max() <= 1e-11 * expected.max()
    assert np.allclose(shapes.mean_shape_index(gpu), shapes.mean_shape_index(cpu), rtol=1e-12, atol=0)
