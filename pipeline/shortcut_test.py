"""The shortcut test a run of the pipeline makes: simplify.shortcut_test,
with `auto` decided once, here, for every job of the run (the Snakefile and
pipeline/regions.py), so that one run never mixes the two tests.

`auto` takes `voronoi` (the eps-Voronoi raster, after the color jobs) where
this machine has a GPU's device node, the one that gl::Context::create_gpu
(gl/context.cpp) looks for before it opens EGL, and `exact` elsewhere. The
jobs are then given the test by name. Where a device node exists but EGL
finds only a software renderer, the jobs' `--gl auto` draws on OSMesa: the
same stores, slower; set `simplify.shortcut_test: exact` there."""
import glob
import os


def gpu_device_node():
    """Whether the machine has /dev/nvidiactl or a render node /dev/dri/renderD*."""
    return os.path.exists("/dev/nvidiactl") or bool(glob.glob("/dev/dri/renderD*"))


def resolve(simplify):
    """(test, why) for the config's simplify section (a dict)."""
    given = simplify.get("shortcut_test", "auto")
    if given != "auto":
        return given, "given"
    if gpu_device_node():
        return "voronoi", "auto: a GPU device node (the raster through EGL)"
    return "exact", "auto: no GPU device node (/dev/nvidiactl, /dev/dri/renderD*): the exact rules on the CPU"
