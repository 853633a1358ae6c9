"""The scene representation and its file format (``docs/scene-format.md``)."""

from abs.scene.load import load_scene
from abs.scene.scene import EnvironmentSpec, ObjectSpec, Prior, RenderSettings, Scene, SensorSpec
from abs.scene.write import write_scene

__all__ = ["load_scene", "write_scene", "Scene", "RenderSettings", "EnvironmentSpec", "ObjectSpec",
           "Prior", "SensorSpec"]
