"""``spherevm info``: versions, and what the GPU path can use on this machine."""
from __future__ import annotations

import json
import os
import sys


def add_parser(subparsers):
    """Register ``info`` on the ``spherevm`` subparsers."""
    i = subparsers.add_parser("info", help="versions, and the device that --device auto picks",
                              description="Print the versions of spherevm and its dependencies and what the "
                                          "GPU path (CuPy, CUDA) can use on this machine.")
    i.add_argument("--json", action="store_true", help="print one JSON object instead")
    i.set_defaults(func=run)
    return i


def _version(dist):
    from importlib.metadata import PackageNotFoundError, version
    try:
        return version(dist)
    except PackageNotFoundError:
        return None


def _cuda_version(raw):
    """CUDA encodes versions as 1000 * major + 10 * minor (12040 -> '12.4')."""
    try:
        n = int(raw)
    except (TypeError, ValueError):
        return str(raw)
    return f"{n // 1000}.{(n % 1000) // 10}"


def collect_info() -> dict:
    """The facts ``spherevm info`` prints (``--json`` prints this dict)."""
    import platform

    import spherevm
    from .. import device
    from ..provenance import source_fingerprint

    facts = device.info()
    out = {
        "spherevm": spherevm.__version__,
        "spherevm_code": source_fingerprint(),
        "spherevm_path": os.path.dirname(os.path.abspath(spherevm.__file__)),
        "python": f"{facts['python']} ({sys.executable})",
        "platform": platform.platform(),
        "numpy": facts["numpy"],
        "scipy": facts["scipy"],
        "gsd": _version("gsd"),
        "trimesh": _version("trimesh"),
        "cupy": facts.get("cupy"),
        "cuda_runtime": _cuda_version(facts["cuda_runtime"]) if facts.get("cuda_runtime") else None,
        "cuda_driver": None,
        "gpus": facts.get("gpus", []),
        "gpu_usable": bool(facts.get("gpu_usable")),
        "gpu_error": facts.get("gpu_error"),
        "auto_device": facts["default_device"],
    }
    if out["cupy"]:
        try:
            import cupy
            out["cuda_driver"] = _cuda_version(cupy.cuda.runtime.driverGetVersion())
        except Exception:
            pass
    return out


def run(args) -> int:
    """The handler of ``spherevm info``."""
    facts = collect_info()
    if args.json:
        print(json.dumps(facts, indent=2))
        return 0
    missing = "not installed"
    cupy = facts["cupy"] or missing
    rows = [
        ("spherevm", f"{facts['spherevm']}, code {facts['spherevm_code']} ({facts['spherevm_path']})"),
        ("python", facts["python"]),
        ("platform", facts["platform"]),
        ("numpy", facts["numpy"]),
        ("scipy", facts["scipy"]),
        ("gsd", facts["gsd"] or missing),
        ("trimesh", facts["trimesh"] or missing),
        ("cupy", cupy),
    ]
    if facts["cupy"]:
        rows.append(("cuda runtime", facts["cuda_runtime"] or "unknown"))
        rows.append(("cuda driver", facts["cuda_driver"] or "unknown"))
        rows.append(("gpus", ", ".join(facts["gpus"]) or "none"))
    gpu = "yes" if facts["gpu_usable"] else "no"
    if not facts["gpu_usable"]:
        gpu += (f" ({facts['gpu_error']})" if facts.get("gpu_error") else
                " (CuPy not installed: pip install 'spherevm[gpu]')" if not facts["cupy"] else "")
    rows.append(("gpu usable", gpu))
    rows.append(("device auto", f"{facts['auto_device']}  (what --device auto / device='auto' picks)"))
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"{key.ljust(width)}  {value}")
    return 0
