"""Named, bounded, physically-typed scene parameters (``glass.absorption``, ``sphere.pose``...)."""

from abs.params.names import POSE_FIELD, Parameter, parameter_specs
from abs.params.setters import Setter

__all__ = ["Parameter", "parameter_specs", "POSE_FIELD", "Setter"]
