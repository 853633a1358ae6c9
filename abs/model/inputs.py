"""A scene and a capture loaded, compiled and checked against the parameter names asked for.

Every run starts by turning paths (or already loaded objects) into a compiled scene and a capture,
and by refusing, with the file and field named, what cannot be fitted: an unknown parameter name,
no parameters at all, or a capture whose every view is held out. Doing it in one place gives every
command the same messages for the same mistakes.
"""

from __future__ import annotations

from pathlib import Path

from abs.errors import InputError

__all__ = ["prepare"]


def prepare(scene, capture, parameters=None):
    """Load (if given paths) and compile a scene and capture; check the parameter names.

    Parameters
    ----------
    scene : Scene or path
        The scene file (TOML) or a loaded scene.
    capture : Capture or path
        The capture folder (``cameras.json``) or a loaded capture.
    parameters : sequence of str, optional
        Parameter names (``glass.absorption``, ``sphere.pose``...); default: the scene's
        ``[fit] parameters``.

    Returns
    -------
    scene : Scene
    compiled : CompiledScene
    capture : Capture
    names : tuple of str

    Raises
    ------
    InputError
        No parameters, an unknown parameter name, or no training view.
    """
    from abs.io.capture import load_capture
    from abs.render import compile_scene
    from abs.scene.load import load_scene

    scene = load_scene(scene) if isinstance(scene, (str, Path)) else scene
    capture = load_capture(capture) if isinstance(capture, (str, Path)) else capture
    names = tuple(parameters) if parameters else scene.fit_parameters
    if not names:
        raise InputError(scene.source, "fit.parameters", "no parameters to fit (give them, or list "
                                                         "them in the scene's [fit] parameters)")
    compiled = compile_scene(scene)
    for name in names:
        if name not in compiled.specs:
            raise InputError(None, "parameters", f"unknown parameter {name!r}; known: "
                                                 f"{', '.join(sorted(compiled.specs))}")
    if not capture.train_views:
        raise InputError(capture.folder / "cameras.json", "views",
                         "every view is a holdout view; nothing to fit")
    return scene, compiled, capture, names
