"""Acquisition: from camera photographs to a capture folder (see docs/acquisition.md).

Board detection (:mod:`.board`), intrinsic calibration (:mod:`.intrinsics`), stereo
(:mod:`.stereo`), extrinsics from a board in the scene (:mod:`.extrinsics`), the camera file
(:mod:`.camera_file`), undistortion (:mod:`.undistort`), raw mosaics (:mod:`.raw`), bilinear and
superpixel demosaicing (:mod:`.demosaic`), bracket merging (:mod:`.hdr`), capture building
(:mod:`.build`) and synthetic board views with known truth (:mod:`.synthetic`).
"""
