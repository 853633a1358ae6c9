"""File formats: images (EXR, HDR, PNG), capture folders, MERL tables, fit outputs."""
