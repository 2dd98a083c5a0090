"""Choosing the OpenGL platform for offscreen rendering, before OpenGL is imported.

PyOpenGL fixes its platform (``PYOPENGL_PLATFORM``: the native window system, ``egl``,
``osmesa``) when it is first imported, and cannot change it afterwards. So the choice is
made here, by probing each candidate in a fresh interpreter, and written into
``PYOPENGL_PLATFORM`` before this process imports pyrender or OpenGL (which only
:mod:`cassi_fit.render._draw` does, when a :class:`~cassi_fit.render.Renderer` is made).
Without a display, EGL comes first, OSMesa second. EGL draws on a GPU when there is one
(a device with a DRM render node), else on Mesa's llvmpipe (software rendering);
``CASSI_EGL_DEVICE`` chooses (:func:`egl_device`).
"""

from __future__ import annotations

import os
import subprocess
import sys
import threading
from collections.abc import Callable, Mapping

from ..errors import RenderingUnavailableError

#: Offscreen OpenGL platforms, in the order tried without a display.
HEADLESS_PLATFORMS = ("egl", "osmesa")

_PLATFORM: str | None = None  # the answer of ensure_headless_gl, cached per process
_DEVICE: dict | None = None  # the EGL device the probe chose: {"device", "file", "renderer"}
_WARM_UP: threading.Thread | None = None  # prepare_gl's thread, if one was started
_CHOSEN = threading.Event()  # set by prepare_gl's thread once the platform is chosen (or not)

# Probes run in a fresh interpreter (PyOpenGL fixes its platform at first import). They
# create a context the way pyrender will (EGL: the first device's platform display) but
# import only PyOpenGL, not pyrender: about 0.1 s instead of 1 s.
_PROBES = {
    "egl": """
import ctypes, json, os, sys
os.environ["PYOPENGL_PLATFORM"] = "egl"
from OpenGL import EGL
def ext(name, restype, *argtypes):
    address = EGL.eglGetProcAddress(name)
    if address is None:
        return None
    function = ctypes.CFUNCTYPE(restype)(address)
    function.argtypes = list(argtypes)
    return function
query = ext("eglQueryDevicesEXT", EGL.EGLBoolean)
devices = []
if query is not None:
    from OpenGL._opaque import opaque_pointer_cls
    device_type = opaque_pointer_cls("EGLDeviceEXT")
    n = EGL.EGLint()
    found = (device_type * 16)()
    query.argtypes = [EGL.EGLint, ctypes.POINTER(device_type), ctypes.POINTER(EGL.EGLint)]
    if query(16, found, ctypes.pointer(n)) and n.value > 0:
        devices = list(found)[: n.value]
get_display = ext("eglGetPlatformDisplayEXT", EGL.EGLDisplay)
name_of = ext("eglQueryDeviceStringEXT", ctypes.c_char_p, ctypes.c_void_p, EGL.EGLint)
def drm_file(device):
    if name_of is None:
        return ""
    name = name_of(ctypes.cast(device, ctypes.c_void_p), 0x3233)  # EGL_DRM_DEVICE_FILE_EXT
    return name.decode() if name else ""
files = [drm_file(d) for d in devices]
wanted = os.environ.get("CASSI_EGL_DEVICE", "auto").strip() or "auto"
if not devices:
    order = [None]
elif wanted == "auto":  # a device with a render node (a GPU) first, the software one last
    order = sorted(range(len(devices)), key=lambda i: (not files[i], i))
elif wanted == "software":
    order = [i for i in range(len(devices)) if not files[i]][:1]
elif wanted.isdigit():
    order = [int(wanted)] if int(wanted) < len(devices) else []
else:
    order = [i for i in range(len(devices)) if files[i] == wanted]
if not order:
    listed = ", ".join(str(i) + " " + (f or "software") for i, f in enumerate(files))
    sys.exit(f"CASSI_EGL_DEVICE={wanted}: no such EGL device (devices: {listed})")
attrs = [EGL.EGL_SURFACE_TYPE, EGL.EGL_PBUFFER_BIT, EGL.EGL_RENDERABLE_TYPE,
         EGL.EGL_OPENGL_BIT, EGL.EGL_DEPTH_SIZE, 24, EGL.EGL_NONE]
failures = []
for index in order:
    display = (EGL.eglGetDisplay(EGL.EGL_DEFAULT_DISPLAY) if index is None
               else get_display(0x313F, devices[index], None))
    try:
        EGL.eglInitialize(display, None, None)
        config, n = EGL.EGLConfig(), EGL.EGLint()
        ok = EGL.eglChooseConfig(display, (EGL.EGLint * len(attrs))(*attrs),
                                 ctypes.pointer(config), 1, ctypes.pointer(n))
        assert ok and n.value > 0, "no EGL configuration with OpenGL and a depth buffer"
        EGL.eglBindAPI(EGL.EGL_OPENGL_API)
        context = EGL.eglCreateContext(display, config, EGL.EGL_NO_CONTEXT, None)
        assert context, "no OpenGL context"
        assert EGL.eglMakeCurrent(display, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, context)
        from OpenGL import GL
        renderer = (GL.glGetString(GL.GL_RENDERER) or b"").decode(errors="replace")
    except Exception as exc:
        failures.append(f"device {index}: {exc}".splitlines()[0])
        continue
    print(json.dumps({"device": index, "file": files[index] if index is not None else "",
                      "renderer": renderer}))
    break
else:
    sys.exit("; ".join(failures))
""",
    "osmesa": """
import os
os.environ["PYOPENGL_PLATFORM"] = "osmesa"
from OpenGL import osmesa
assert osmesa.OSMesaCreateContextExt(osmesa.OSMESA_RGBA, 24, 0, 0, None), "no OSMesa context"
""",
    "native": """
import os
os.environ.pop("PYOPENGL_PLATFORM", None)
import pyrender
pyrender.OffscreenRenderer(16, 16).delete()
""",
}


def probe_gl_platform(platform: str) -> str | None:
    """Try an offscreen context with ``platform`` (``"native"``, ``"egl"``, ``"osmesa"``)
    in a fresh interpreter; ``None`` if a context was created, else the reason (one line).
    EGL: on the device :func:`egl_device` describes (``CASSI_EGL_DEVICE``), remembered
    for :func:`ensure_headless_gl`.

    PyOpenGL fixes its platform at first import, so each candidate needs its own process.
    """
    try:
        proc = subprocess.run(
            [sys.executable, "-c", _PROBES[platform]], capture_output=True, text=True,
            timeout=120, start_new_session=True,  # a Ctrl-C is this process's to handle
        )
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{type(exc).__name__}: {exc}"
    if proc.returncode == 0:
        if platform == "egl":
            _remember_device(proc.stdout)
        return None
    lines = [ln.strip() for ln in proc.stderr.strip().splitlines() if ln.strip()]
    return lines[-1] if lines else f"exit code {proc.returncode}"


def _has_display(environ: Mapping[str, str]) -> bool:
    return bool(environ.get("DISPLAY") or environ.get("WAYLAND_DISPLAY"))


def _imported_platform(platform_object: object, environ: Mapping[str, str]) -> str:
    """The platform of an already imported PyOpenGL (its ``OpenGL.platform.PLATFORM``),
    if pyrender can use it."""
    name = type(platform_object).__name__.lower()
    for platform in HEADLESS_PLATFORMS:
        if name.startswith(platform):
            return platform
    if _has_display(environ):
        return "native"
    raise RenderingUnavailableError(
        f"OpenGL was imported (platform {name}) before cassi_fit.render could choose a "
        "headless one: import cassi_fit.render first, or set PYOPENGL_PLATFORM=egl"
    )


def _opengl_platform_object() -> object | None:
    """PyOpenGL's platform object if PyOpenGL is imported already, else None."""
    module = sys.modules.get("OpenGL.platform")
    return None if module is None else module.PLATFORM


def choose_gl_platform(
    *,
    probe: Callable[[str], str | None] = probe_gl_platform,
    environ: Mapping[str, str] | None = None,
    imported: object = ...,
) -> str:
    """The OpenGL platform offscreen rendering should use (no caching, nothing changed).

    A ``PYOPENGL_PLATFORM`` in ``environ`` (default ``os.environ``) is respected as is.
    If PyOpenGL is imported already (``imported``: its ``OpenGL.platform.PLATFORM``, or
    None for "not imported"; by default looked up in ``sys.modules``), its platform is the
    answer, or a
    :class:`RenderingUnavailableError` if pyrender cannot use it. Otherwise the
    candidates are, in order: ``"native"`` (only with ``DISPLAY``/``WAYLAND_DISPLAY``),
    ``"egl"``, ``"osmesa"``, each tried with ``probe``; none working is one
    :class:`RenderingUnavailableError` line naming each candidate's reason.
    """
    environ = os.environ if environ is None else environ
    if environ.get("PYOPENGL_PLATFORM"):
        return environ["PYOPENGL_PLATFORM"]
    imported = _opengl_platform_object() if imported is ... else imported
    if imported is not None:  # too late to choose: PyOpenGL has its platform
        return _imported_platform(imported, environ)
    candidates = ["native"] * _has_display(environ) + list(HEADLESS_PLATFORMS)
    failures = []
    for platform in candidates:
        reason = probe(platform)
        if reason is None:
            return platform
        failures.append(f"{platform} ({reason})")
    raise RenderingUnavailableError(
        f"no offscreen OpenGL: tried {'; '.join(failures)}. Install Mesa EGL (apt install "
        "libegl1 libgl1-mesa-dri) or OSMesa (libosmesa6), or set PYOPENGL_PLATFORM"
    )


def _remember_device(stdout: str) -> None:
    global _DEVICE
    import json

    lines = [ln for ln in stdout.splitlines() if ln.startswith("{")]
    _DEVICE = json.loads(lines[-1]) if lines else None


def egl_device() -> dict | None:
    """The EGL device this process draws on, once :func:`ensure_headless_gl` chose EGL:
    ``{"device": index (pyrender's EGL_DEVICE_ID) or None, "file": its DRM render node
    ("" for Mesa's software device), "renderer": OpenGL's GL_RENDERER string, e.g.
    "llvmpipe (LLVM 15.0.7, 256 bits)"}``; None if not known (another platform, or
    ``PYOPENGL_PLATFORM`` set without ``CASSI_EGL_DEVICE``).

    The device is chosen by ``CASSI_EGL_DEVICE``: ``auto`` (default) the first device
    with a DRM render node (a GPU) that makes a context, else Mesa's software one
    (llvmpipe); ``software`` llvmpipe; a number, that device; a path such as
    ``/dev/dri/renderD128``, the device with that render node. ``EGL_DEVICE_ID`` set by
    hand is respected as pyrender reads it."""
    return None if _DEVICE is None else dict(_DEVICE)


def ensure_headless_gl(*, imports: bool = True) -> str:
    """Choose the OpenGL platform for offscreen rendering (:func:`choose_gl_platform`),
    once per process; returns its name.

    A headless choice is written into ``PYOPENGL_PLATFORM`` before pyrender or OpenGL
    are imported here. Raises :class:`RenderingUnavailableError` (one line) if no
    platform works. ``imports=False``: where :func:`prepare_gl` runs, wait for its
    choice only, not for its imports (a caller that only hands the choice on, to
    drawing processes).
    """
    global _PLATFORM
    warm_up = _WARM_UP
    if warm_up is not None and warm_up is not threading.current_thread():
        # prepare_gl's choice (or its failure, made again here to be said)
        while not imports and warm_up.is_alive() and not _CHOSEN.wait(0.05):
            pass
        if imports or not _CHOSEN.is_set():
            warm_up.join()
    if _PLATFORM is None:
        platform = choose_gl_platform()
        if (platform == "egl" and _DEVICE is None and os.environ.get("CASSI_EGL_DEVICE")
                and "OpenGL.platform" not in sys.modules):
            reason = probe_gl_platform("egl")  # PYOPENGL_PLATFORM set: choose the device
            if reason is not None:
                raise RenderingUnavailableError(f"no EGL context: {reason}")
        if platform != "native" and "OpenGL.platform" not in sys.modules:
            os.environ["PYOPENGL_PLATFORM"] = platform
        if (platform == "egl" and _DEVICE is not None and _DEVICE.get("device") is not None
                and "EGL_DEVICE_ID" not in os.environ):
            os.environ["EGL_DEVICE_ID"] = str(_DEVICE["device"])  # read by pyrender
        _PLATFORM = platform
    return _PLATFORM


def prepare_gl() -> None:
    """Start choosing the OpenGL platform (:func:`ensure_headless_gl`: a probe in a
    subprocess) and importing pyrender, OpenGL and :mod:`cassi_fit.render._draw` (about
    a second, in the order a Renderer imports them) in a background thread, so that a :class:`~cassi_fit.render.Renderer` made
    later in this process finds them done: a command that will draw calls it before its
    other work (fitting, animating), which mostly runs outside Python's lock (XLA) and
    leaves the time free. Nothing else changes: the same choice, the same modules; a
    failure here is left for the Renderer's own call to raise (its
    :func:`ensure_headless_gl` waits for this thread first). Once per process; no-op
    when the platform is chosen already."""
    global _WARM_UP
    if _WARM_UP is not None or _PLATFORM is not None:
        return

    def work() -> None:
        try:
            try:
                ensure_headless_gl()
            finally:
                _CHOSEN.set()
            # in Renderer._build_scene's order: pyrender (and OpenGL with its error
            # checking) first, then _draw, which turns the checking off for what follows
            import pyrender  # noqa: F401

            from . import _draw  # noqa: F401
        except Exception:  # noqa: BLE001 -- said by the Renderer's own ensure_headless_gl
            pass

    _WARM_UP = threading.Thread(target=work, name="cassi-prepare-gl", daemon=True)
    _WARM_UP.start()
