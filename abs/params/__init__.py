"""Named, bounded, physically-typed scene parameters (``glass.absorption``, ``sphere.pose``...)."""

from abs.params.names import OBJECT_FIELDS, PLACEMENT_FIELD, POSE_FIELD, Parameter, parameter_specs
from abs.params.setters import Setter

__all__ = ["Parameter", "parameter_specs", "POSE_FIELD", "PLACEMENT_FIELD", "OBJECT_FIELDS", "Setter"]
