"""File formats: images (EXR, HDR, PNG), capture folders, MERL tables, shared data.

Low in the layers (docs/architecture.md): io imports nothing from abs but :mod:`abs.errors` and
the sRGB transfer functions and tone mapping of :mod:`abs.colour`. Run folders (fit outputs,
checkpoints) are :mod:`abs.runs`.
"""
