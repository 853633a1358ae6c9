"""``abs glass rgb``: per-channel optical constants of a material from its spectral data.

Reads a refractiveindex.info YAML file, integrates n, k and the Beer-Lambert absorption
``4πk/λ`` against the normalised CIE 1931 RGB colour-matching functions
(:mod:`abs.colour.spectral`) and prints (or writes) a ``[materials.NAME]`` table for a scene
file, with a comment naming its source, so a fit starts from physics-based values.
"""

from __future__ import annotations

import json
from pathlib import Path


def add_parser(sub) -> None:
    p = sub.add_parser("glass", help="spectral optical constants to per-channel scene values")
    commands = p.add_subparsers(dest="glass_command", required=True)
    rgb = commands.add_parser("rgb", help="refractiveindex.info YAML -> [materials.NAME] (ior, "
                                          "absorption in 1/m; or eta, k for a conductor)")
    rgb.add_argument("yaml", type=Path, help="refractiveindex.info material file (.yml)")
    rgb.add_argument("--name", default="glass", help="material name in the table (default %(default)s)")
    rgb.add_argument("--type", choices=("dielectric", "conductor"), default="dielectric",
                     help="scene material type: dielectric writes ior and absorption, conductor "
                          "writes eta and k (default %(default)s)")
    rgb.add_argument("--out", type=Path, help="write the TOML table here (default: print it)")
    rgb.add_argument("--json", type=Path, help="also write every derived value as JSON")
    rgb.set_defaults(run=run_rgb)


def material_table(values: dict, name: str, kind: str) -> str:
    """The ``[materials.NAME]`` TOML text for :func:`abs.colour.optical_constants_rgb` values."""
    import tomli_w

    if kind == "dielectric":
        table = {"type": "dielectric", "ior": values["ior_rgb"], "absorption": values["absorption_per_m"]}
    else:
        table = {"type": "conductor", "eta": values["ior_rgb"], "k": values["k_rgb"]}
    refs = " ".join(values["references"].split())
    header = (f"# {name}: from {values['source']}\n# ({refs[:200]})\n"
              f"# per R, G, B: spectra averaged with the normalised {values['cmfs']} (abs glass rgb)\n")
    return header + tomli_w.dumps({"materials": {name: table}})


def run_rgb(args) -> int:
    from abs.colour import optical_constants_rgb, read_refractiveindex_yaml

    values = optical_constants_rgb(read_refractiveindex_yaml(args.yaml))
    text = material_table(values, args.name, args.type)
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(text)
        print(f"wrote {args.out}")
    else:
        print(text, end="")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(values, indent=2) + "\n")
    return 0
