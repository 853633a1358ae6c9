"""The scene representation and its file format (``docs/scene-format.md``)."""

from abs.scene.load import load_scene
from abs.scene.scene import EnvironmentSpec, ObjectSpec, RenderSettings, Scene

__all__ = ["load_scene", "Scene", "RenderSettings", "EnvironmentSpec", "ObjectSpec"]
