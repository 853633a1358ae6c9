"""Named, bounded, physically-typed scene parameters (``glass.absorption``, ``sphere.pose``...)."""

from abs.params.names import Parameter, parameter_specs

__all__ = ["Parameter", "parameter_specs"]
