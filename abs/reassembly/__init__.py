"""Reassembly: glass scanned in a CT put back into the scene it was photographed in
(see docs/reassembly.md).

Volume files (:mod:`.volume`), a synthetic CT phantom with known truth (:mod:`.phantom`),
thresholds and iso-surfaces (:mod:`.surfaces`), RANSAC sphere fits of the markers
(:mod:`.spheres`), mesh cleaning: carving, hole filling, decimation, √3 subdivision
(:mod:`.cleaning`), the whole meshing step (:mod:`.meshing`), markers in calibrated stereo
photographs: circle detection (:mod:`.circles`), Sampson matching (:mod:`.epipolar`),
triangulation and clustering (:mod:`.triangulation`), the seen-through-glass check
(:mod:`.through_glass`) and the whole stereo step (:mod:`.stereo_markers`), synthetic marker
photographs for tests (:mod:`.marker_images`), marker pairing and Kabsch
placement (:mod:`.placement`), suspect markers after placement (:mod:`.suspect_markers`), the
placed object written into a scene file (:mod:`.scene_pose`), the soft deformation of a
tablecloth under a hard object (:mod:`.deform`), and micropolygon labelling of a background mesh:
segmentation of the photographs (:mod:`.segmentation`), labels per face (:mod:`.labelling`),
their files (:mod:`.label_files`) and a background of known materials for tests
(:mod:`.label_truth`).

Units: millimetres in the CT volume and in everything measured in it (marker centres, radii, the
glass mesh before it is written for a scene); metres in scene files and for triangulated markers.
"""
