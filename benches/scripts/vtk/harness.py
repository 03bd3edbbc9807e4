#!/usr/bin/env python3
"""VTK reference harness for the shearwarp crate.

Renders a rotation sequence of a VolPack .den volume with VTK's CPU ray
caster (vtkFixedPointVolumeRayCastMapper) and prints ONE JSON line with
per-frame timings on stdout, using the same volume, classification, shading,
views and zoom as benches/scripts/volpack/harness.c (see benches/scripts/vtk/README.md for
what can and cannot be matched).  Everything else goes to stderr.

Only renWin.Render() is timed.  Needs python3 with the `vtk` wheel (>= 9.1)
and numpy; runs off-screen (EGL, e.g. Mesa llvmpipe) without a display, or
under `xvfb-run -a` (GLX) if EGL is unavailable.
"""

import argparse
import json
import math
import os
import re
import struct
import subprocess
import sys
import time

PROG = "harness.py"

# Material / light, identical to benches/scripts/volpack/harness.c
MAT_AMBIENT = 0.10
MAT_DIFFUSE = 0.60
MAT_SPECULAR = 0.30
MAT_SHININESS = 20.0

DEN_HEADER = 62
# vtkFixedPointVolumeRayCastMapper stops a ray once the remaining
# transparency (15-bit fixed point) drops below 0xff: opacity > 1 - 255/32768.
VTK_MAX_RAY_OPACITY = 1.0 - 255.0 / 32768.0


def die(msg, code=2):
    print(f"{PROG}: {msg}", file=sys.stderr)
    sys.exit(code)


def log(msg):
    print(f"{PROG}: {msg}", file=sys.stderr, flush=True)


# ---------------------------------------------------------------------------
# .den input (same rules as load_den() in benches/scripts/volpack/harness.c)

def load_den(path):
    """Return (bytes of nx*ny*nz u8 voxels, x fastest, (nx, ny, nz))."""
    try:
        with open(path, "rb") as f:
            buf = f.read()
    except OSError as e:
        die(f"cannot read {path}: {e.strerror or e}")
    if len(buf) < DEN_HEADER:
        die(f"{path}: too short for a .den file ({len(buf)} bytes, header is {DEN_HEADER})")
    version_le = struct.unpack_from("<H", buf, 0)[0]
    if version_le == 1:
        end = "<"
    elif version_le == 0x0100:
        end = ">"  # byte-swapped header (big-endian writer)
    else:
        die(f"{path}: not a .den file (bad map_version 0x{version_le:04x})")
    dims = struct.unpack_from(end + "3h", buf, 50)  # map_len[3]
    count = struct.unpack_from(end + "I", buf, 58)[0]
    if min(dims) <= 0:
        die(f"{path}: inconsistent .den header (map_len = {dims})")
    n = dims[0] * dims[1] * dims[2]
    if n != count:
        die(f"{path}: inconsistent .den header (map_len {dims[0]}x{dims[1]}x{dims[2]}"
            f" = {n} voxels, voxel count field says {count})")
    have = len(buf) - DEN_HEADER
    if have < n:
        die(f"{path}: truncated .den data ({have} of {n} voxel bytes present)")
    if have > n:
        log(f"warning: {path} has {have - n} trailing bytes after the voxels (ignored)")
    return buf[DEN_HEADER:DEN_HEADER + n], tuple(int(d) for d in dims)


# ---------------------------------------------------------------------------
# statistics (same definitions as the VolPack harness)

def median(v):
    s = sorted(v)
    n = len(s)
    if n == 0:
        return 0.0
    return s[n // 2] if n % 2 else 0.5 * (s[n // 2 - 1] + s[n // 2])


def percentile_nearest_rank(v, p):
    s = sorted(v)
    n = len(s)
    if n == 0:
        return 0.0
    k = int(math.ceil(p / 100.0 * n)) - 1
    return s[min(max(k, 0), n - 1)]


# ---------------------------------------------------------------------------

def parse_args(argv):
    ap = argparse.ArgumentParser(
        prog=PROG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Render a rotation sequence of a VolPack .den volume with VTK's\n"
            "vtkFixedPointVolumeRayCastMapper (CPU ray casting, trilinear, shaded)\n"
            "and print one JSON line with per-frame timings (only renWin.Render()\n"
            "is timed).  Classification, shading, views and zoom match\n"
            "benches/scripts/volpack/harness.c; see benches/scripts/vtk/README.md."),
        epilog=(
            "opacity (d = 8-bit density, T = --threshold):\n"
            "  opaque: alpha = clamp((d - T)/4, 0, 1)\n"
            "  ramp:   alpha = A * clamp((d - T)/(E - T), 0, 1)   (A=--ramp-top, E=--ramp-end)\n"
            "  entries with alpha <= --min-opacity are set to 0 (VolPack's\n"
            "  VP_MIN_VOXEL_OPACITY); colour is constant white (grey image).\n"
            "view: frame f rotates the volume (its user matrix, set from scratch each\n"
            "  frame) by VolPack's R_y(f*step) about its centre dims/2; orthographic\n"
            "  camera looking along +z, image rows increasing with +y (frame 0 of\n"
            "  brainsmall = left profile, frame 90 = face).\n"
            "render path: --backend auto uses EGL when $DISPLAY is unset, else the X\n"
            "  window (run under `xvfb-run -a` if there is no EGL); the path used is\n"
            "  reported as \"render_path\" in the JSON.\n"
            "example:\n"
            "  python3 benches/scripts/vtk/harness.py --den brainsmall.den --size 512 \\\n"
            "      --frames 60 --threads 2 --tf opaque"))
    ap.add_argument("--den", metavar="FILE", required=True,
                    help="VolPack .den volume (u8, 62-byte header)")
    ap.add_argument("--name", metavar="NAME",
                    help="volume name for the JSON and PNG names (default: file stem)")
    ap.add_argument("--tf", choices=("opaque", "ramp"), default="opaque",
                    help="classification (default opaque)")
    ap.add_argument("--threshold", type=float, default=24.0, metavar="T",
                    help="density threshold T (default 24)")
    ap.add_argument("--ramp-top", type=float, default=0.3, metavar="A",
                    help="ramp: opacity reached at density E (default 0.3)")
    ap.add_argument("--ramp-end", type=float, default=255.0, metavar="E",
                    help="ramp: density where the ramp tops out (default 255)")
    ap.add_argument("--min-opacity", type=float, default=0.05, metavar="V",
                    help="table entries with alpha <= V become 0, like VolPack's "
                         "VP_MIN_VOXEL_OPACITY (default 0.05; 0 disables)")
    ap.add_argument("--size", type=int, default=512, metavar="N",
                    help="image N x N (default 512)")
    ap.add_argument("--fit", choices=("diag", "maxdim"), default="diag",
                    help="zoom: bounding-box diagonal = image width (default), or "
                         "largest dimension = image width")
    ap.add_argument("--frames", type=int, default=360, metavar="F",
                    help="timed frames (default 360)")
    ap.add_argument("--step-deg", type=float, default=1.0, metavar="S",
                    help="rotation step about the volume's y axis per frame (default 1)")
    ap.add_argument("--warmup", type=int, default=1, metavar="W",
                    help="untimed frames (view of frame 0) before timing (default 1); "
                         "the first one is reported as setup_ms")
    ap.add_argument("--threads", type=int, default=0, metavar="T",
                    help="ray-casting threads (mapper SetNumberOfThreads); 0 = VTK's "
                         "default (all cores).  T > 0 also caps vtkSMPTools and "
                         "llvmpipe (LP_NUM_THREADS, unless already set)")
    ap.add_argument("--backend", choices=("auto", "egl", "osmesa", "x"), default="auto",
                    help="OpenGL window: auto (default: EGL if $DISPLAY is unset, "
                         "else X/GLX), egl, osmesa, x")
    ap.add_argument("--frames-out", metavar="DIR",
                    help="write the frames listed by --save-frames as PNG into DIR")
    ap.add_argument("--save-frames", default="0,45", metavar="LIST",
                    help="comma-separated frame indices to save (default 0,45)")
    ap.add_argument("--perspective", type=float, metavar="FOV",
                    help="perspective camera with this vertical field of view in degrees "
                         "(0 < FOV < 180) instead of the orthographic one")
    ap.add_argument("--eye-distance", type=float, default=2.0, metavar="D",
                    help="with --perspective: the eye's distance from the volume's centre "
                         "in volume diagonals (default 2; shearwarp's --eye-distance)")
    ap.add_argument("--times", action="store_true",
                    help="also print every frame time in the JSON")
    ap.add_argument("--views", metavar="FILE",
                    help="shearwarp's matched views (`shearwarp bench --peers`): a JSON list of "
                         "{\"name\": N, \"matrix\": [9 numbers, row-major]}, each the volume's "
                         "rotation about its voxel-centre (dims-1)/2, rendered --warmup + --reps "
                         "times and saved as DIR/<name>.png with --frames-out DIR; needs --zoom. "
                         "Replaces the rotation sequence (--frames, --step-deg, --fit)")
    ap.add_argument("--reps", type=int, default=3, metavar="R",
                    help="with --views: timed renders per view (default 3)")
    ap.add_argument("--zoom", type=float, metavar="Z",
                    help="with --views: image pixels per voxel (shearwarp's resolved zoom); "
                         "pixel (c, r) samples ((c - (N-1)/2)/Z, ((N-1)/2 - r)/Z) as shearwarp's do")
    ap.add_argument("--eye-voxels", type=float, metavar="D",
                    help="with --views and --perspective: the eye's distance from the volume's "
                         "centre in voxels (shearwarp's resolved distance; replaces --eye-distance)")
    a = ap.parse_args(argv)

    if not 1 <= a.size <= 16384:
        ap.error("--size must be in 1..16384")
    if a.frames < 0 or a.warmup < 0:
        ap.error("--frames and --warmup must be >= 0")
    if a.threads < 0:
        ap.error("--threads must be >= 0")
    if not math.isfinite(a.step_deg):
        ap.error("bad --step-deg")
    if a.perspective is not None and not 0.0 < a.perspective < 180.0:
        ap.error("--perspective must be in (0, 180) degrees")
    if not (math.isfinite(a.eye_distance) and a.eye_distance > 0.0):
        ap.error("--eye-distance must be a finite number of diagonals > 0")
    if a.tf == "ramp" and not a.ramp_end > a.threshold:
        ap.error("--ramp-end must exceed --threshold")
    try:
        a.save_set = {int(s) for s in a.save_frames.split(",") if s.strip() != ""}
    except ValueError:
        ap.error(f"bad --save-frames {a.save_frames!r}")
    a.view_list = None
    if a.views is not None:
        if a.zoom is None or not (math.isfinite(a.zoom) and a.zoom > 0.0):
            ap.error("--views needs --zoom Z (finite, > 0)")
        if a.reps < 1:
            ap.error("--reps must be >= 1")
        if a.eye_voxels is not None and not (math.isfinite(a.eye_voxels) and a.eye_voxels > 0.0):
            ap.error("--eye-voxels must be finite and > 0")
        if a.perspective is not None and a.eye_voxels is None:
            ap.error("--views with --perspective needs --eye-voxels D")
        try:
            with open(a.views) as f:
                vl = json.load(f)
        except (OSError, ValueError) as e:
            ap.error(f"cannot read --views {a.views}: {e}")
        if not isinstance(vl, list) or not vl:
            ap.error(f"--views {a.views}: expected a non-empty JSON list")
        a.view_list = []
        for i, v in enumerate(vl):
            m = v.get("matrix") if isinstance(v, dict) else None
            nm = v.get("name") if isinstance(v, dict) else None
            if not isinstance(nm, str) or not re.fullmatch(r"[A-Za-z0-9_.+-]+", nm) or \
                    not isinstance(m, list) or len(m) != 9 or \
                    not all(isinstance(x, (int, float)) and math.isfinite(x) for x in m):
                ap.error(f"--views {a.views}: entry {i} needs a file-safe \"name\" and a "
                         f"\"matrix\" of 9 finite numbers")
            a.view_list.append((nm, [float(x) for x in m]))
    return a


def opacity_table(a):
    """256 opacities, exactly VolPack's density_table (+ min-opacity cut)."""
    tab = []
    for d in range(256):
        if a.tf == "opaque":
            alpha = min(max((d - a.threshold) / 4.0, 0.0), 1.0)
        else:
            alpha = a.ramp_top * (d - a.threshold) / (a.ramp_end - a.threshold)
            alpha = min(max(alpha, 0.0), a.ramp_top)
        if alpha <= a.min_opacity:
            alpha = 0.0
        tab.append(alpha)
    return tab


def xvfb_serving(display):
    """True if an Xvfb process serves `display` (e.g. ':99')."""
    m = re.match(r"^[^:]*:(\d+)", display or "")
    if not m:
        return False
    num = m.group(1)
    try:
        pids = [p for p in os.listdir("/proc") if p.isdigit()]
    except OSError:
        return False
    for p in pids:
        try:
            with open(f"/proc/{p}/cmdline", "rb") as f:
                argv = f.read().split(b"\0")
        except OSError:
            continue
        if argv and os.path.basename(argv[0]) == b"Xvfb" and \
                any(x == f":{num}".encode() for x in argv[1:]):
            return True
    return False


# A missing EGL/OSMesa library or X server can crash VTK (segfault) instead of
# failing cleanly, so each candidate window class is tried in a child process.
PROBE = r"""
import sys
from vtkmodules.vtkCommonCore import vtkOutputWindow
from vtkmodules.vtkRenderingCore import vtkRenderer, vtkRenderWindow
import vtkmodules.vtkRenderingOpenGL2
vtkOutputWindow.GetInstance().SetDisplayModeToAlwaysStdErr()
w = vtkRenderWindow()
w.SetOffScreenRendering(1)
w.SetMultiSamples(0)
w.SetSize(16, 16)
w.AddRenderer(vtkRenderer())
if not w.SupportsOpenGL():
    sys.exit(3)
w.Render()
print(w.GetClassName())
"""

WINDOW_CLASSES = {"egl": "vtkEGLRenderWindow", "osmesa": "vtkOSOpenGLRenderWindow",
                  "x": "vtkXOpenGLRenderWindow"}


def choose_window(backend, display):
    """Return (VTK window class that works, probe log)."""
    if backend != "auto":
        order = [backend]
    elif os.environ.get("VTK_DEFAULT_OPENGL_WINDOW"):
        order = [os.environ["VTK_DEFAULT_OPENGL_WINDOW"]]
    elif display:
        order = ["x", "egl", "osmesa"]   # e.g. under xvfb-run
    else:
        order = ["egl", "osmesa"]        # pure off-screen
    logs = []
    for b in order:
        cls = WINDOW_CLASSES.get(b, b)
        if cls == "vtkXOpenGLRenderWindow" and not display:
            logs.append(f"{cls}: no $DISPLAY")
            continue
        env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW=cls)
        try:
            r = subprocess.run([sys.executable, "-c", PROBE], env=env, timeout=120,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        except (OSError, subprocess.TimeoutExpired) as e:
            logs.append(f"{cls}: {e}")
            continue
        got = r.stdout.decode(errors="replace").strip().splitlines()
        if r.returncode == 0 and got and got[-1] == cls:
            logs.append(f"{cls}: ok")
            return cls, logs
        why = f"exit {r.returncode}" if r.returncode >= 0 else f"signal {-r.returncode}"
        if r.returncode == 0 and got:
            why = f"VTK fell back to {got[-1]}"
        err = [ln for ln in r.stderr.decode(errors="replace").splitlines()
               if "not found" in ln or "ERR" in ln or "rror" in ln]
        logs.append(f"{cls}: failed ({why}{'; ' + err[-1].strip() if err else ''})")
    for ln in logs:
        log(ln)
    die("no working OpenGL window for VTK's image display; install EGL (libegl1 + "
        "libegl-mesa0) or run under Xvfb: `apt-get install -y xvfb` and "
        "`xvfb-run -a python3 benches/scripts/vtk/harness.py ...`", 1)


def main(argv):
    a = parse_args(argv)

    voxels, dims = load_den(a.den)
    nx, ny, nz = dims
    name = a.name or os.path.basename(a.den).split(".")[0]

    try:
        import numpy as np
        from vtkmodules.vtkCommonCore import (vtkCommand, vtkOutputWindow, vtkSMPTools,
                                              vtkVersion, VTK_UNSIGNED_CHAR)
        from vtkmodules.vtkCommonDataModel import vtkImageData, vtkPiecewiseFunction
        from vtkmodules.vtkCommonMath import vtkMatrix4x4
        from vtkmodules.vtkRenderingCore import (vtkLight, vtkRenderer, vtkRenderWindow,
                                                 vtkVolume, vtkVolumeProperty,
                                                 vtkWindowToImageFilter)
        from vtkmodules.vtkRenderingVolume import vtkFixedPointVolumeRayCastMapper
        import vtkmodules.vtkRenderingOpenGL2  # noqa: F401  (OpenGL factories)
        import vtkmodules.vtkRenderingVolumeOpenGL2  # noqa: F401  (image display helper)
        from vtkmodules.vtkIOImage import vtkPNGWriter
        from vtkmodules.vtkImagingCore import vtkImageExtractComponents
        from vtkmodules.util.numpy_support import numpy_to_vtk
    except ImportError as e:
        die(f"cannot import VTK/numpy ({e}); install with `python3 -m pip install vtk numpy`")

    # ---- choose the OpenGL window before VTK creates one (read at New()) ----
    display = os.environ.get("DISPLAY", "")
    if a.threads > 0 and "LP_NUM_THREADS" not in os.environ:
        os.environ["LP_NUM_THREADS"] = str(a.threads)  # Mesa llvmpipe threads
    win_class, probe_log = choose_window(a.backend, display)
    os.environ["VTK_DEFAULT_OPENGL_WINDOW"] = win_class
    log(f"OpenGL window {win_class} (probe: {'; '.join(probe_log)})")
    gl_threads_env = os.environ.get("LP_NUM_THREADS")

    vtkOutputWindow.GetInstance().SetDisplayModeToAlwaysStdErr()
    if a.threads > 0:
        vtkSMPTools.Initialize(a.threads)

    # ---- volume: unit spacing, voxel i at world i - dims/2 (VolPack's centre) ----
    img = vtkImageData()
    img.SetDimensions(nx, ny, nz)
    img.SetSpacing(1.0, 1.0, 1.0)
    if a.view_list is None:
        img.SetOrigin(-nx / 2.0, -ny / 2.0, -nz / 2.0)
    else:  # shearwarp rotates about the voxel-centre box's centre
        img.SetOrigin(-(nx - 1) / 2.0, -(ny - 1) / 2.0, -(nz - 1) / 2.0)
    arr = np.frombuffer(voxels, dtype=np.uint8)
    varr = numpy_to_vtk(arr, deep=1, array_type=VTK_UNSIGNED_CHAR)
    varr.SetName("density")
    img.GetPointData().SetScalars(varr)
    del voxels

    # ---- classification: 256-entry opacity table, white colour ----
    otab = opacity_table(a)
    opacity = vtkPiecewiseFunction()
    for d, alpha in enumerate(otab):
        opacity.AddPoint(float(d), alpha)
    grey = vtkPiecewiseFunction()
    grey.AddPoint(0.0, 1.0)
    grey.AddPoint(255.0, 1.0)

    prop = vtkVolumeProperty()
    prop.SetScalarOpacity(opacity)
    prop.SetColor(grey)
    prop.SetScalarOpacityUnitDistance(1.0)  # alpha per voxel length, like VolPack
    prop.SetInterpolationTypeToLinear()
    prop.ShadeOn()
    prop.SetAmbient(MAT_AMBIENT)
    prop.SetDiffuse(MAT_DIFFUSE)
    prop.SetSpecular(MAT_SPECULAR)
    prop.SetSpecularPower(MAT_SHININESS)

    mapper = vtkFixedPointVolumeRayCastMapper()
    mapper.SetInputData(img)
    mapper.SetBlendModeToComposite()
    mapper.AutoAdjustSampleDistancesOff()
    mapper.LockSampleDistanceToInputSpacingOff()
    mapper.SetSampleDistance(1.0)
    mapper.SetInteractiveSampleDistance(1.0)
    mapper.SetImageSampleDistance(1.0)
    mapper.SetMinimumImageSampleDistance(1.0)
    mapper.SetMaximumImageSampleDistance(1.0)
    mapper.IntermixIntersectingGeometryOff()
    if a.threads > 0:
        mapper.SetNumberOfThreads(a.threads)
    # the multi-threaded ray casting proper (RenderSubVolume) is bracketed by
    # these events; the rest of Render() is serial set-up and display
    cast = {"t0": None, "ms": None}

    def cast_start(_obj, _ev):
        cast["t0"] = time.perf_counter()

    def cast_end(_obj, _ev):
        if cast["t0"] is not None:
            cast["ms"] = (time.perf_counter() - cast["t0"]) * 1e3
    mapper.AddObserver(vtkCommand.VolumeMapperRenderStartEvent, cast_start)
    mapper.AddObserver(vtkCommand.VolumeMapperRenderEndEvent, cast_end)

    vol = vtkVolume()
    vol.SetMapper(mapper)
    vol.SetProperty(prop)

    # ---- renderer, one white headlight ----
    ren = vtkRenderer()
    ren.SetBackground(0.0, 0.0, 0.0)
    ren.AutomaticLightCreationOff()
    ren.TwoSidedLightingOn()  # |n.l|, like VolPack's VP_BOTH_SIDES
    light = vtkLight()
    light.SetLightTypeToHeadlight()
    light.SetAmbientColor(1.0, 1.0, 1.0)  # vtkLight's default ambient colour is black
    light.SetDiffuseColor(1.0, 1.0, 1.0)
    light.SetSpecularColor(1.0, 1.0, 1.0)
    light.SetIntensity(1.0)
    ren.AddLight(light)
    ren.AddVolume(vol)

    # ---- camera: orthographic, looking along +z, up = -y ----
    diag = math.sqrt(nx * nx + ny * ny + nz * nz)
    maxdim = max(dims)
    scale = 0.5 * diag if a.fit == "diag" else 0.5 * maxdim  # half image height, voxels
    px_per_voxel = a.size / (2.0 * scale)
    # VTK casts through pixel centres ((c + 0.5 - N/2)/s); VolPack puts
    # (col, row) at (c - N/2)/s.  Shift the camera by half a pixel to match.
    h = 0.5 / px_per_voxel
    # shearwarp's perspective: the eye on the view axis eye_distance
    # diagonals from the centre, the vertical field of view over the image
    # height; near plane 0.5 voxel in front of the eye (or the volume)
    eye = a.eye_distance * diag
    if a.view_list is not None:
        # shearwarp's own camera: pixel centres (c - (N-1)/2)/Z are VTK's
        # (c + 0.5 - N/2)/s with s = Z, so no half-pixel shift; its eye distance
        px_per_voxel = a.zoom
        scale = a.size / (2.0 * a.zoom)
        h = 0.0
        eye = a.eye_voxels
    dist = diag + 10.0
    cam = ren.GetActiveCamera()
    if a.perspective is None:
        cam.ParallelProjectionOn()
        cam.SetFocalPoint(-h, -h, 0.0)
        cam.SetPosition(-h, -h, -dist)
        cam.SetViewUp(0.0, -1.0, 0.0)
        cam.SetParallelScale(scale)
        cam.SetClippingRange(dist - 0.5 * diag - 2.0, dist + 0.5 * diag + 2.0)
    else:
        cam.ParallelProjectionOff()
        cam.SetFocalPoint(0.0, 0.0, 0.0)
        cam.SetPosition(0.0, 0.0, -eye)
        cam.SetViewUp(0.0, -1.0, 0.0)
        cam.SetViewAngle(a.perspective)
        cam.SetClippingRange(max(0.5, eye - 0.5 * diag - 2.0), eye + 0.5 * diag + 2.0)

    renwin = vtkRenderWindow()
    renwin.SetOffScreenRendering(1)
    renwin.SetMultiSamples(0)
    renwin.SetSize(a.size, a.size)
    renwin.AddRenderer(ren)
    if renwin.GetClassName() != win_class:
        log(f"warning: asked VTK for {win_class}, got {renwin.GetClassName()}")

    def set_matrix(r):
        m = vtkMatrix4x4()
        m.DeepCopy((r[0], r[1], r[2], 0.0,
                    r[3], r[4], r[5], 0.0,
                    r[6], r[7], r[8], 0.0,
                    0.0, 0.0, 0.0, 1.0))
        vol.SetUserMatrix(m)

    def set_view(f):
        t = math.radians(f * a.step_deg)
        c, s = math.cos(t), math.sin(t)
        m = vtkMatrix4x4()  # VolPack's vpRotate(VP_Y_AXIS): x'=cx-sz, z'=sx+cz
        m.DeepCopy((c, 0.0, -s, 0.0,
                    0.0, 1.0, 0.0, 0.0,
                    s, 0.0, c, 0.0,
                    0.0, 0.0, 0.0, 1.0))
        vol.SetUserMatrix(m)

    w2i = vtkWindowToImageFilter()
    w2i.SetInput(renwin)
    w2i.SetInputBufferTypeToRGB()
    w2i.ReadFrontBufferOff()
    w2i.ShouldRerenderOff()
    if a.frames_out:
        try:
            os.makedirs(a.frames_out, exist_ok=True)
        except OSError as e:
            die(f"cannot create {a.frames_out}: {e.strerror or e}")

    def save_png(f, file_name=None):
        w2i.Modified()
        w2i.Update()
        out = w2i.GetOutput()
        pix = out.GetPointData().GetScalars()
        rgb = np.frombuffer(memoryview(pix), dtype=np.uint8).reshape(-1, 3) \
            if pix is not None else None
        src = w2i
        if rgb is not None and np.array_equal(rgb[:, 0], rgb[:, 1]) and \
                np.array_equal(rgb[:, 0], rgb[:, 2]):
            ext = vtkImageExtractComponents()  # grey image -> 8-bit luminance PNG
            ext.SetInputConnection(w2i.GetOutputPort())
            ext.SetComponents(0)
            src = ext
        path = os.path.join(a.frames_out, file_name or f"vtk_{name}_{a.tf}_{a.size}_f{f:03d}.png")
        wr = vtkPNGWriter()
        wr.SetFileName(path)
        wr.SetInputConnection(src.GetOutputPort())
        wr.Write()
        if wr.GetErrorCode():
            die(f"write failed on {path}", 1)
        log(f"wrote {path}")

    # ---- frames ----
    setup_ms = None
    render_ms, mapper_ms, finish_ms, cast_ms = [], [], [], []
    nimg = 0
    per_view = []

    def timed_render():
        cast["t0"] = cast["ms"] = None
        t0 = time.perf_counter()
        renwin.Render()
        t1 = time.perf_counter()
        renwin.WaitForCompletion()  # glFinish, outside frame_ms
        return (t1 - t0) * 1e3, (time.perf_counter() - t1) * 1e3

    # shearwarp's matched views: warm-up renders of each view, then --reps timed ones
    for vname, mat in a.view_list or []:
        set_matrix(mat)
        for w in range(a.warmup):
            ms, _ = timed_render()
            if setup_ms is None:
                setup_ms = ms
        times = []
        for _ in range(a.reps):
            ms, fin = timed_render()
            times.append(ms)
            render_ms.append(ms)
            finish_ms.append(fin)
            mapper_ms.append(mapper.GetTimeToDraw() * 1e3)
            if cast["ms"] is not None:
                cast_ms.append(cast["ms"])
        if a.frames_out:
            save_png(0, f"{vname}.png")
            nimg += 1
        per_view.append({"name": vname, "frame_ms_median": round(median(times), 4),
                         "frame_ms_min": round(min(times), 4), "reps": a.reps})
    for i in range(-a.warmup, a.frames if a.view_list is None else 0):
        f = max(i, 0)
        set_view(f)
        cast["t0"] = cast["ms"] = None
        t0 = time.perf_counter()
        renwin.Render()
        t1 = time.perf_counter()
        renwin.WaitForCompletion()  # glFinish, outside frame_ms
        t2 = time.perf_counter()
        if i < 0:
            if setup_ms is None:
                setup_ms = (t1 - t0) * 1e3
            continue
        render_ms.append((t1 - t0) * 1e3)
        finish_ms.append((t2 - t1) * 1e3)
        mapper_ms.append(mapper.GetTimeToDraw() * 1e3)
        if cast["ms"] is not None:
            cast_ms.append(cast["ms"])
        if a.frames_out and f in a.save_set:
            save_png(f)
            nimg += 1

    # ---- what actually ran ----
    if a.warmup == 0 and a.frames == 0:
        renwin.Render()
    win_class = renwin.GetClassName()
    caps = renwin.ReportCapabilities() or ""
    mm = re.search(r"OpenGL renderer string:\s*(.*)", caps)
    gl_renderer = mm.group(1).strip() if mm else None
    if win_class == "vtkEGLRenderWindow":
        render_path = "offscreen-egl"
    elif win_class == "vtkOSOpenGLRenderWindow":
        render_path = "offscreen-osmesa"
    elif win_class == "vtkXOpenGLRenderWindow":
        render_path = "xvfb" if xvfb_serving(display) else "x11"
        render_path += "-glx-offscreen" if renwin.GetOffScreenRendering() else "-glx"
    else:
        render_path = win_class
    threads_used = mapper.GetNumberOfThreads()
    log(f"render path {render_path} ({win_class}, {gl_renderer}, DISPLAY={display or '-'}), "
        f"{threads_used} ray-casting thread(s)")

    n = len(render_ms)
    rnd = lambda x, k=4: None if x is None else round(x, k)  # noqa: E731
    if a.tf == "opaque":
        tf_params = {"kind": "opaque", "threshold": a.threshold, "ramp_width": 4,
                     "opacity": f"clamp((d-{a.threshold:g})/4,0,1)"}
    else:
        tf_params = {"kind": "ramp", "threshold": a.threshold, "ramp_end": a.ramp_end,
                     "ramp_top": a.ramp_top,
                     "opacity": f"{a.ramp_top:g}*clamp((d-{a.threshold:g})/"
                                f"({a.ramp_end:g}-{a.threshold:g}),0,1)"}
    out = {
        "renderer": "vtk",
        "mapper": "vtkFixedPointVolumeRayCastMapper",
        "volume": name,
        "dims": [nx, ny, nz],
        "size": a.size,
        "tf": a.tf,
        "frames": a.frames,
        "setup_ms": rnd(setup_ms, 3),
        "frame_ms_median": rnd(median(render_ms)),
        "frame_ms_mean": rnd(sum(render_ms) / n if n else 0.0),
        "frame_ms_p90": rnd(percentile_nearest_rank(render_ms, 90.0)),
        "frame_ms_min": rnd(min(render_ms) if n else 0.0),
        "frame_ms_max": rnd(max(render_ms) if n else 0.0),
        "mapper_ms_median": rnd(median(mapper_ms)),
        "raycast_ms_median": rnd(median(cast_ms)) if cast_ms else None,
        "finish_ms_median": rnd(median(finish_ms)),
        "tf_params": tf_params,
        "min_voxel_opacity": a.min_opacity,
        "max_ray_opacity": round(VTK_MAX_RAY_OPACITY, 6),
        "view": {"projection": "orthographic" if a.perspective is None else
                 {"perspective": a.perspective, "eye_distance": a.eye_distance},
                 "axis": "y", "step_deg": a.step_deg,
                 "fit": a.fit, "parallel_scale": round(scale, 6),
                 "px_per_voxel": round(px_per_voxel, 6), "warmup": a.warmup,
                 "rotation": "volume user matrix R_y (VolPack sign), about dims/2"},
        "shading": {"model": "blinn-phong", "light": "headlight", "two_sided": True,
                    "ambient": MAT_AMBIENT, "diffuse": MAT_DIFFUSE,
                    "specular": MAT_SPECULAR, "shininess": MAT_SHININESS,
                    "depth_cue": False},
        "sampling": {"interpolation": "trilinear", "sample_distance": 1.0,
                     "image_sample_distance": 1.0, "auto_adjust": False,
                     "opacity_unit_distance": 1.0},
        "threads": threads_used,
        "threads_requested": a.threads,
        "gl_threads": gl_threads_env,
        "vtk_version": vtkVersion.GetVTKVersion(),
        "render_path": render_path,
        "render_window": win_class,
        "gl_renderer": gl_renderer,
        "timed": "renWin.Render()",
        "images_written": nimg,
    }
    if a.view_list is not None:
        out["frames"] = len(render_ms)
        out["views"] = per_view
        out["view"]["projection"] = "orthographic" if a.perspective is None else \
            {"perspective": a.perspective, "eye_voxels": a.eye_voxels}
        out["view"]["rotation"] = "volume user matrix per --views entry, about (dims-1)/2"
        out["view"]["px_per_voxel"] = a.zoom
    if a.times:
        out["frame_ms"] = [round(x, 4) for x in render_ms]
    sys.stdout.write(json.dumps(out, separators=(",", ":")) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except KeyboardInterrupt:
        die("interrupted", 130)
