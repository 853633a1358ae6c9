"""Write a labelled mesh for the scene file: one PLY per label, ``labels.json``, a scene-file
snippet, and optionally a scene with the background object replaced by its labelled parts.

The scene format (docs/scene-format.md) gives an object one material and has no per-face
material ids, so a labelled mesh becomes one object per label.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from abs.errors import InputError
from abs.reassembly.labelling import LabelResult
from abs.scene import load_scene, write_scene
from abs.scene.scene import ObjectSpec

__all__ = ["write_labelling", "check_label_scene", "replace_with_labels"]


def write_labelling(result: LabelResult, colours: np.ndarray, out: str | Path,
                    materials: list[str] | None = None, name: str = "background") -> Path:
    """Write ``label_<k>.ply`` per label, ``face_labels.npy``, ``labels.json`` and
    ``scene_snippet.toml`` into ``out``.

    Parameters
    ----------
    result : LabelResult
    colours : (n, 3) array
        Each label's mean linear RGB in the photographs.
    out : path
        Folder, created if missing.
    materials : list of str, optional
        Material name of label ``k`` at ``k - 1``. Without it the snippet defines diffuse
        materials ``label_<k>`` whose reflectance is the photographed colour scaled so that the
        brightest channel of all is 0.8: a starting value for a fit, not a measurement (the
        photographs hold reflectance times light).
    name : str
        Prefix of the snippet's object names (``<name>_<k>``).

    Returns
    -------
    Path
        ``labels.json``.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    n = len(colours)
    if materials is not None and len(materials) != n:
        raise InputError(None, "--materials", f"{len(materials)} names for {n} labels")
    mesh, labels = result.mesh, result.face_labels
    areas = mesh.area_faces
    entries, snippet = [], ["# written by `abs reassemble label`: one object per label (the scene "
                            "format has no per-face materials)", ""]
    if materials is None:
        scale = 0.8 / max(float(np.max(colours)), 1e-12)
        for k in range(1, n + 1):
            rgb = ", ".join(f"{v:.4f}" for v in np.clip(colours[k - 1] * scale, 0, 1))
            snippet += [f"[materials.label_{k}]  # starting value from the photographs, fit it",
                        'type = "diffuse"', f"reflectance = [{rgb}]", ""]
    for k in range(1, n + 1):
        faces = np.flatnonzero(labels == k)
        ply = f"label_{k}.ply"
        if len(faces):
            mesh.submesh([faces], append=True).export(out / ply)
        material = materials[k - 1] if materials is not None else f"label_{k}"
        entries.append({"label": k, "faces": int(len(faces)), "area_m2": float(areas[faces].sum()),
                        "colour_linear": colours[k - 1].tolist(), "material": material,
                        "mesh": ply if len(faces) else None})
        if len(faces):
            snippet += ["[[objects]]", f'name = "{name}_{k}"', f'mesh = "{ply}"',
                        f'material = "{material}"', ""]
    np.save(out / "face_labels.npy", labels)
    mesh.export(out / "labelled.ply")
    (out / "scene_snippet.toml").write_text("\n".join(snippet), encoding="utf-8")
    report = {"labels": entries, "faces": int(len(labels)),
              "faces_by_nearest_neighbour": int(np.count_nonzero(~result.voted)),
              "subdivision_rounds": result.rounds, "worst_edge_footprints": result.worst_edge_px,
              "vertices_on_a_label_per_view": result.votes_per_view,
              "mesh": "labelled.ply", "face_labels": "face_labels.npy"}
    path = out / "labels.json"
    path.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    return path


def check_label_scene(scene_path: str | Path, name: str, materials: list[str]):
    """The scene of ``scene_path``, checked to hold object ``name`` and every material named.

    Raises
    ------
    InputError
        No object ``name``, or a material the scene does not define.
    """
    scene = load_scene(scene_path)
    names = [o.name for o in scene.objects]
    if name not in names:
        raise InputError(scene_path, "objects", f"no object {name!r}; objects are {', '.join(names)}")
    for m in materials:
        if m not in scene.materials:
            raise InputError(scene_path, f"materials.{m}", "no such material; the scene has "
                                                          f"{', '.join(sorted(scene.materials))}")
    return scene


def replace_with_labels(scene_path: str | Path, out: str | Path, name: str, folder: str | Path,
                        materials: list[str]) -> Path:
    """Write ``out``: the scene of ``scene_path`` with object ``name`` replaced by one object per
    label (``<name>_<k>``, mesh ``folder/label_<k>.ply``, material ``materials[k - 1]``).

    Raises
    ------
    InputError
        No object ``name``, or a material the scene does not define.
    """
    scene = check_label_scene(scene_path, name, materials)
    names = [o.name for o in scene.objects]
    # the labelled meshes are in the world frame (the cameras'): the parts get no to_world
    parts = [ObjectSpec(f"{name}_{k}", (Path(folder) / f"label_{k}.ply").resolve(), m, np.eye(4))
             for k, m in enumerate(materials, start=1) if (Path(folder) / f"label_{k}.ply").is_file()]
    i = names.index(name)
    objects = list(scene.objects[:i]) + parts + list(scene.objects[i + 1:])
    return write_scene(replace(scene, objects=tuple(objects)), out)
