"""Variant selection and the LLVM set-up."""

from __future__ import annotations

import os
import subprocess
import sys

import mitsuba as mi

from abs.render.variant import find_libllvm


def _python(code: str, **env) -> subprocess.CompletedProcess:
    full = {k: v for k, v in os.environ.items() if k not in ("ABS_VARIANT", "DRJIT_LIBLLVM_PATH")}
    full.update(env)
    return subprocess.run([sys.executable, "-c", code], env=full, capture_output=True, text=True, timeout=120)


def test_finds_a_recent_llvm():
    path = find_libllvm()
    assert path is not None and os.path.isfile(path)


def test_default_is_llvm_without_gpu():
    assert mi.variant() in ("llvm_ad_rgb", "cuda_ad_rgb")
    out = _python("import abs.render, mitsuba as mi, os; print(mi.variant(), os.environ['DRJIT_LIBLLVM_PATH'])")
    assert out.returncode == 0, out.stderr
    variant, llvm = out.stdout.split()
    assert variant in ("llvm_ad_rgb", "cuda_ad_rgb") and "LLVM" in llvm


def test_environment_variable_and_argument():
    out = _python("import abs.render, mitsuba as mi; print(mi.variant())", ABS_VARIANT="llvm_ad_rgb")
    assert out.stdout.strip() == "llvm_ad_rgb", out.stderr
    out = _python("from abs.render.variant import set_variant; set_variant('no_such_variant')")
    assert out.returncode != 0 and "unknown Mitsuba variant 'no_such_variant'" in out.stderr


def test_too_old_llvm_is_explained():
    out = _python("from abs.render.variant import set_variant; set_variant('llvm_ad_rgb')",
                  DRJIT_LIBLLVM_PATH="/usr/lib/x86_64-linux-gnu/libLLVM-15.so")
    assert out.returncode != 0 and "libllvm19" in out.stderr
