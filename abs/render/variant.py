"""Choose and activate the Mitsuba variant, and make Dr.Jit find a usable LLVM.

Dr.Jit's CPU backend JIT-compiles through ``libLLVM``. Version 15 (Debian 12's default) aborts
with ``LLVM ERROR: Cannot select ... fminimum`` and version 14 is refused as too old; Debian's
``libllvm19`` works. We point ``DRJIT_LIBLLVM_PATH`` at the newest suitable library when the
user has not, and explain the problem when none is installed, because the raw abort gives no
hint of its cause.

Selection order: the ``variant`` argument, then the ``ABS_VARIANT`` environment variable, then
``cuda_ad_rgb`` when a CUDA device is usable, else ``llvm_ad_rgb``.
"""

from __future__ import annotations

import glob
import os
import re

__all__ = ["DEFAULT_VARIANT", "ENV_VARIABLE", "find_libllvm", "set_variant", "current_variant",
           "current_backend"]

DEFAULT_VARIANT = "llvm_ad_rgb"
ENV_VARIABLE = "ABS_VARIANT"
MIN_LLVM_MAJOR = 16
_LIB_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
)
_SETUP_HINT = (
    "Dr.Jit's CPU backend needs libLLVM >= {min} (Debian 12's LLVM 15 aborts with "
    "'Cannot select ... fminimum'). Install it with `apt-get install libllvm19`, or set "
    "DRJIT_LIBLLVM_PATH to a libLLVM.so of version >= {min}."
)


def _major(path: str) -> int | None:
    match = re.search(r"libLLVM(?:-|\.so\.)(\d+)", os.path.basename(path))
    return int(match.group(1)) if match else None


def find_libllvm() -> str | None:
    """Return the path of the newest installed libLLVM of version >= 16, or ``None``."""
    found: dict[int, str] = {}
    for pattern in _LIB_GLOBS:
        for path in sorted(glob.glob(pattern)):
            major = _major(path)
            if major is not None and major >= MIN_LLVM_MAJOR and os.path.isfile(path):
                found.setdefault(major, path)
    return found[max(found)] if found else None


def _configure_llvm() -> None:
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return
    path = find_libllvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path


def _cuda_usable() -> bool:
    import mitsuba as mi

    if "cuda_ad_rgb" not in mi.variants():
        return False
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # noqa: BLE001 - any driver failure means "not usable"
        return False


def current_variant() -> str | None:
    """The active Mitsuba variant, or ``None`` if none is set."""
    import mitsuba as mi

    return mi.variant()


def current_backend() -> str:
    """``"cuda"`` when the active variant (activated first if none is) runs on a GPU, else
    ``"llvm"``: the key of settings that differ by backend."""
    return "cuda" if (current_variant() or set_variant()).startswith("cuda") else "llvm"


def set_variant(variant: str | None = None) -> str:
    """Activate a Mitsuba variant for abs and return its name.

    Parameters
    ----------
    variant : str, optional
        ``"llvm_ad_rgb"`` or ``"cuda_ad_rgb"``. When omitted, ``$ABS_VARIANT`` decides, else
        CUDA when a GPU is usable, else LLVM.

    Raises
    ------
    RuntimeError
        When the LLVM variant is requested but no suitable libLLVM is installed.
    """
    _configure_llvm()
    import mitsuba as mi

    name = variant or os.environ.get(ENV_VARIABLE) or None
    if name is None:
        name = "cuda_ad_rgb" if _cuda_usable() else DEFAULT_VARIANT
    if name not in mi.variants():
        raise ValueError(f"unknown Mitsuba variant {name!r}; available: {', '.join(mi.variants())}")
    if name.startswith("llvm"):
        llvm = os.environ.get("DRJIT_LIBLLVM_PATH")
        major = _major(llvm) if llvm else None
        if llvm is None or (major is not None and major < MIN_LLVM_MAJOR):
            raise RuntimeError(_SETUP_HINT.format(min=MIN_LLVM_MAJOR))
    if mi.variant() != name:
        mi.set_variant(name)
    return name
