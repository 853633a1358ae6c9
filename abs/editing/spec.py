"""The target-material grammar of ``abs edit --to`` and :func:`abs.editing.edit`.

A spec is ``KIND`` or ``KIND:ARGUMENT`` (case-insensitive kind, argument kept as written):

============================  =================================================================
spec                          edit (Khan et al. 2006 baseline)
============================  =================================================================
``glossier``                  highlights remapped with alpha 0.05, beta 20 (:mod:`~abs.editing.gloss`)
``diffuse``                   highlights remapped with alpha 0.05, beta 0.05
``glass`` = ``glass:clear``   the warped background shows through, highlights kept
``glass:frosted``             ... blurred a little
``glass:tinted``              ... with the object's colour transferred onto it
``glass:dark``                ... darkened, ``C_max (C / C_max)^a``
``translucent``               the warped background blurred a lot, highlights kept
``merl:NAME``                 a measured BRDF (the shared MERL fits, or ``--merl-dir``) lit by the
                              photograph's environment, ~400 directions per pixel
``texture:FILE``              the image FILE as the object's new texture (matting equation)
============================  =================================================================
"""

from __future__ import annotations

from dataclasses import dataclass

from abs.errors import InputError

__all__ = ["KINDS", "GLASS_VARIANTS", "MaterialSpec", "parse_material"]

KINDS = ("glossier", "diffuse", "glass", "translucent", "merl", "texture")
"""The kinds of target material."""
GLASS_VARIANTS = ("clear", "frosted", "tinted", "dark")
"""The variants of ``glass``."""

GRAMMAR = ("glossier, diffuse, glass[:clear|frosted|tinted|dark], translucent, merl:NAME, "
           "texture:FILE")


@dataclass(frozen=True)
class MaterialSpec:
    """A parsed target material.

    Attributes
    ----------
    kind : str
        One of :data:`KINDS`.
    argument : str or None
        The glass variant, the MERL material's name or the texture file; ``None`` otherwise.
    """

    kind: str
    argument: str | None = None

    def __str__(self) -> str:
        return self.kind if self.argument is None else f"{self.kind}:{self.argument}"


def parse_material(text: str, field: str = "to") -> MaterialSpec:
    """Parse a target-material spec (module docstring).

    Parameters
    ----------
    text : str
        The spec, e.g. ``"glass:tinted"`` or ``"merl:blue-rubber"``.
    field : str
        Field the errors name (``--to`` for the command).

    Raises
    ------
    InputError
        For an unknown kind or variant, a missing or superfluous argument.
    """
    if not isinstance(text, str) or not text.strip():
        raise InputError(None, field, f"empty material; expected one of {GRAMMAR}")
    kind, sep, argument = text.strip().partition(":")
    kind = kind.strip().lower()
    argument = argument.strip() if sep else None
    if kind not in KINDS:
        raise InputError(None, field, f"unknown material {kind!r}; expected one of {GRAMMAR}")
    if kind == "glass":
        variant = (argument or "clear").lower()
        if variant not in GLASS_VARIANTS:
            raise InputError(None, field, f"unknown glass {variant!r}; expected glass:"
                                          f"{'|'.join(GLASS_VARIANTS)}")
        return MaterialSpec("glass", variant)
    if kind in ("merl", "texture"):
        if not argument:
            what = "a MERL material name, e.g. merl:blue-rubber" if kind == "merl" else \
                "an image file, e.g. texture:wood.exr"
            raise InputError(None, field, f"{kind} needs {what}")
        return MaterialSpec(kind, argument)
    if argument:
        raise InputError(None, field, f"{kind} takes no argument, got {argument!r}")
    return MaterialSpec(kind)
