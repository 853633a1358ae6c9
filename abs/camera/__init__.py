"""OpenCV pinhole camera helpers in numpy (projection, look-at, intrinsics)."""
