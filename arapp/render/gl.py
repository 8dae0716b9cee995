"""OpenGL platform selection and offscreen context creation (pyrender's platforms).

PyOpenGL binds its platform (EGL, OSMesa, GLX) once, when `OpenGL` is first
imported, from the environment variable PYOPENGL_PLATFORM. So the choice is made
here, before anything imports OpenGL or pyrender:

1. PYOPENGL_PLATFORM if the user set it (or whatever PyOpenGL is already bound to);
2. EGL when libEGL is installed and can initialise a display: headless Mesa
   (llvmpipe) on servers and CI, the GPU driver's EGL on a desktop;
3. OSMesa (pure software) when EGL is missing or does not initialise (also when PYOPENGL_PLATFORM=egl
   was asked for but EGL does not work, as long as OpenGL is not imported yet).

When none works, `RendererError` names the Debian/Ubuntu packages to install.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import warnings

INSTALL_HINT = (
    "install libegl1 and libgl1-mesa-dri (Debian/Ubuntu: `apt-get install libegl1 libgl1-mesa-dri`; "
    "Fedora: mesa-libEGL mesa-dri-drivers) for headless EGL, or libosmesa6 for the OSMesa software "
    "fallback (then run with PYOPENGL_PLATFORM=osmesa); on a desktop with a GPU, install the driver's "
    "EGL library (e.g. libnvidia-gl-<version>)"
)

SUPPORTED = ("egl", "osmesa")


class RendererError(RuntimeError):
    """The overlay renderer cannot run: no OpenGL platform, or a bad argument to the renderer."""


def _bound_platform() -> str | None:
    """The platform PyOpenGL is already bound to in this process, or None if OpenGL is not imported yet."""
    mod = sys.modules.get("OpenGL.platform")
    if mod is None or getattr(mod, "PLATFORM", None) is None:
        return None
    name = type(mod.PLATFORM).__name__.lower()
    for key in ("egl", "osmesa", "glx", "win", "darwin"):
        if key in name:
            return key
    return name


def _egl_initialises() -> bool:
    """True when libEGL loads and eglInitialize succeeds on a display, tried the way pyrender opens one
    (the first EGL device, headless) and then on the default display. ctypes only, so PyOpenGL stays
    unbound if EGL does not work."""
    path = ctypes.util.find_library("EGL")
    if not path:
        return False
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return False
    vp = ctypes.c_void_p
    lib.eglGetProcAddress.restype = vp
    lib.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    lib.eglGetDisplay.restype = vp
    lib.eglGetDisplay.argtypes = [vp]
    lib.eglInitialize.argtypes = [vp, vp, vp]
    displays = []
    query = lib.eglGetProcAddress(b"eglQueryDevicesEXT")
    get_platform_display = lib.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
    if query and get_platform_display:
        query_fn = ctypes.CFUNCTYPE(ctypes.c_uint, ctypes.c_int, ctypes.POINTER(vp), ctypes.POINTER(ctypes.c_int))(query)
        gpd_fn = ctypes.CFUNCTYPE(vp, ctypes.c_uint, vp, vp)(get_platform_display)
        devices = (vp * 8)()
        n = ctypes.c_int(0)
        if query_fn(8, devices, ctypes.byref(n)) and n.value > 0:
            displays.append(gpd_fn(0x313F, devices[0], None))  # EGL_PLATFORM_DEVICE_EXT
    displays.append(lib.eglGetDisplay(None))
    # the display is left initialised: terminating it would break any EGL context someone else holds
    return any(dpy and lib.eglInitialize(dpy, None, None) for dpy in displays)


def _osmesa_present() -> bool:
    path = ctypes.util.find_library("OSMesa")
    if not path:
        return False
    try:
        ctypes.CDLL(path)
    except OSError:
        return False
    return True


def select_platform() -> str:
    """Choose the GL platform ('egl' or 'osmesa') and set PYOPENGL_PLATFORM accordingly.

    Raises RendererError naming the packages to install when no platform is usable.
    """
    bound = _bound_platform()
    requested = os.environ.get("PYOPENGL_PLATFORM", "").strip().lower()
    if bound is not None:
        if bound not in SUPPORTED:
            raise RendererError(
                f"PyOpenGL is already bound to the {bound!r} platform in this process (something imported "
                f"OpenGL or pyrender before the renderer chose a platform); the offscreen overlay renderer "
                f"needs EGL or OSMesa. Set PYOPENGL_PLATFORM=egl (or osmesa) before starting; {INSTALL_HINT}"
            )
        return bound
    if requested:
        if requested not in SUPPORTED:
            raise RendererError(
                f"PYOPENGL_PLATFORM={requested!r} is not an offscreen platform the overlay renderer supports "
                f"(use 'egl' or 'osmesa', or unset it to choose automatically); {INSTALL_HINT}"
            )
        if requested == "osmesa" or _egl_initialises():
            return requested
        # EGL asked for (the Makefile's default) but not working here: OpenGL is not bound yet, so
        # OSMesa can still take over
        if _osmesa_present():
            warnings.warn("EGL does not initialise on this machine; rendering with OSMesa (software, slower)",
                          RuntimeWarning, stacklevel=3)
            os.environ["PYOPENGL_PLATFORM"] = "osmesa"
            return "osmesa"
        raise RendererError(f"PYOPENGL_PLATFORM=egl but EGL does not initialise, and OSMesa is missing: {INSTALL_HINT}")
    if _egl_initialises():
        choice = "egl"
    elif _osmesa_present():
        choice = "osmesa"
    else:
        raise RendererError(f"no offscreen OpenGL platform works (EGL and OSMesa both unavailable): {INSTALL_HINT}")
    os.environ["PYOPENGL_PLATFORM"] = choice
    return choice


def create_context(width: int, height: int):
    """An offscreen GL core context (4.1 with EGL, 3.3 with OSMesa) made current, from pyrender's platform classes.

    Returns (platform_object, platform_name). The default framebuffer is not used (the renderer draws
    into its own framebuffer objects), so the pbuffer size hardly matters.
    """
    name = select_platform()
    try:
        if name == "egl":
            from pyrender.platforms import egl  # the platform tried decides which GL module may load

            device = egl.get_default_device()
            plat = egl.EGLPlatform(width, height, device=device)
        else:
            from pyrender.platforms.osmesa import OSMesaPlatform  # OSMesa: only where EGL is not used

            plat = OSMesaPlatform(width, height)
        plat.init_context()
        plat.make_current()
    except RendererError:
        raise
    except Exception as e:  # noqa: BLE001 - PyOpenGL/EGL raise many unrelated types; all mean "no context"
        raise RendererError(
            f"could not create an offscreen OpenGL context with PYOPENGL_PLATFORM={name} "
            f"({type(e).__name__}: {e}); {INSTALL_HINT}"
        ) from e
    return plat, name


def release_context(plat, name: str) -> None:
    """Destroy a context from create_context().

    pyrender's EGLPlatform.delete_context() also calls eglTerminate on the display, which every EGL
    context of this process on that device shares (other renderers, pyrender's own OffscreenRenderer):
    it would break them. So only the context is destroyed; the display stays initialised until exit.
    """
    if name != "egl":
        plat.delete_context()
        return
    from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent  # EGL platform only

    dpy, ctx = plat._egl_display, plat._egl_context
    if dpy is None:
        return
    plat._egl_context = None
    plat._egl_display = None
    try:
        eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)
        if ctx is not None:
            eglDestroyContext(dpy, ctx)
    except Exception:  # noqa: BLE001 - display already terminated by someone else: the context is gone
        pass
