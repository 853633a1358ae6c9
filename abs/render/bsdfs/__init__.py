"""abs's own Mitsuba BSDF plugins, registered by name on import.

========================  ===================================================================
plugin                    what
========================  ===================================================================
``abs_dielectric``        smooth glass, one IOR per colour channel, Beer-Lambert absorption
``abs_diffuse``           Lambertian with an anisotropic lobe of woven threads (``anisotropy``)
``abs_tabulated``         isotropic measured BRDF table in MERL layout (differentiable values)
========================  ===================================================================
"""

from abs.render.bsdfs import dielectric, diffuse, tabulated  # noqa: F401  (registration side effect)
