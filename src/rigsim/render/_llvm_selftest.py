"""Self-test of one libLLVM for Mitsuba's llvm variants. Run ONLY in a child process.

Usage: python _llvm_selftest.py VARIANT   (with DRJIT_LIBLLVM_PATH set by the parent)

A bad libLLVM can abort the interpreter (SIGABRT inside LLVM codegen, e.g. libLLVM 15/16 with
drjit 1.5.0 at the first ``dr.minimum`` kernel), so this file is executed by
:mod:`rigsim.render.backend` in a subprocess and its exit status is the verdict. It prints one
JSON line starting with ``RIGSIM-SELFTEST`` on success. This file must not import rigsim.
"""

from __future__ import annotations

import json
import os
import sys


def main() -> int:
    variant = sys.argv[1] if len(sys.argv) > 1 else "llvm_ad_mono"
    import drjit as dr
    import mitsuba as mi

    if not dr.has_backend(dr.JitBackend.LLVM):
        print("llvm backend not available (library refused by drjit)", file=sys.stderr)
        return 3
    mi.set_variant(variant)

    # 1. a kernel using dr.minimum / dr.maximum (drjit 1.5 emits llvm.minimum; LLVM 15/16 abort)
    x = mi.Float([0.25, 2.0, -1.0, 3.5])
    y = dr.minimum(dr.maximum(x, 0.0), 1.5) * 2.0
    dr.eval(y)
    got = [float(v) for v in y]
    if got != [0.5, 3.0, 0.0, 3.0]:
        print(f"wrong kernel result {got}", file=sys.stderr)
        return 4

    # 2. a tiny render: a diffuse emitter filling an 8x8 perspective view
    scene = mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {
            "type": "perspective", "fov": 20.0,
            "film": {"type": "hdrfilm", "width": 8, "height": 8,
                     "rfilter": {"type": "box"}, "pixel_format": "luminance"},
            "sampler": {"type": "independent", "sample_count": 4},
        },
        "wall": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f().translate([0.0, 0.0, 10.0]).rotate([1, 0, 0], 180.0)
            .scale([100.0, 100.0, 1.0]),
            "emitter": {"type": "area", "radiance": {"type": "uniform", "value": 2.0}},
        },
    })
    img = mi.render(scene, spp=4)
    dr.eval(img)
    import numpy as np

    arr = np.asarray(img, dtype=np.float64)
    mean = float(arr.mean())
    # mono/rgb give exactly 2.0; spectral variants estimate luminance from 4 random wavelengths
    tol = 1e-3 if ("mono" in variant or "rgb" in variant) else 0.5
    if not abs(mean - 2.0) < tol:
        print(f"wrong render mean {mean}", file=sys.stderr)
        return 5
    print("RIGSIM-SELFTEST " + json.dumps({
        "variant": variant, "render_mean": mean,
        "libllvm": os.environ.get("DRJIT_LIBLLVM_PATH", ""),
        "mitsuba": mi.__version__, "drjit": dr.__version__,
    }))
    return 0


if __name__ == "__main__":
    sys.exit(main())
