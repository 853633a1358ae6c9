"""abs's renderer against plain Mitsuba, measured in one run: compile, speed, derivatives, memory.

Every figure is a ratio to Mitsuba 3's own ``path`` integrator on the same scene, measured in the
same run on the same machine (absolute seconds are printed beside). Rows:

- **compile**: the first render of a view, each in a fresh process with an empty Dr.Jit kernel
  cache (what a new user waits for), abs against Mitsuba's first ``path`` render; for the default
  scene and for a scene with ``merl`` and ``brdf_pca`` materials.
- **primal**: samples per second once compiled, with one scalar IOR (Mitsuba's ``dielectric``).
- **dispersion**: distinct IORs per channel. abs splits a path at the first dispersive glass it
  meets (one channel per path onwards); the alternative is one full render per channel. Compared
  at equal noise: efficiency = 1 / (pixel variance x time), variance from independent seeds.
- **derivatives**: a forward-mode Jacobian column and a path-replay gradient, in primal renders.
- **memory**: peak resident memory of a gradient (path replay) and of a Jacobian column on a
  640x480 view at 1, 16 and 256 spp, each in a fresh process (empty kernel cache, so the growth
  includes compiling the kernels), above the process's footprint after compiling the scene.

    python benchmarks/render_speed.py [--quick]

Writes ``benchmarks/results/render_speed.json`` and prints the table the README shows.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import textwrap
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENE = ROOT / "scenes/default/scene.toml"

# Run in a child process: one measurement, printed as JSON on the last line.
_CHILD = textwrap.dedent('''
    import json, sys, time
    import numpy as np
    import abs.render
    import drjit as dr, mitsuba as mi
    from abs.render import Camera, compile_scene
    from abs.scene import load_scene
    from abs.simulate import place_cameras

    task, scene_path, width, height, spp = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    compiled = compile_scene(load_scene(scene_path))
    view = place_cameras(compiled, 1, width, height)[0]
    camera = Camera(view["K"], view["R"], view["t"], width, height)
    def rss():  # this process's peak resident memory since the last reset, MB (Linux)
        for line in open("/proc/self/status"):
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    def reset_peak():  # loading the scene peaks above a render; count from here (Linux >= 4.0)
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
    def gpu_mb():  # the GPU's used memory, MB: Dr.Jit keeps freed blocks, so after a render it is
        # that render's high-water mark (the benchmark's process is the GPU's only user)
        if not mi.variant().startswith("cuda"):
            return None
        import subprocess
        out = subprocess.run(["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                             capture_output=True, text=True, check=True).stdout
        return float(out.split()[0])
    out = {}
    if task == "abs_first":
        start = time.perf_counter(); compiled.render(camera, spp=spp).numpy()
        out["seconds"] = time.perf_counter() - start
    elif task == "mitsuba_first":
        sys.path.insert(0, sys.argv[6]); from render_speed import mitsuba_scene
        scene = mitsuba_scene(compiled, view, width, height, ior=None)
        start = time.perf_counter(); np.array(mi.render(scene, spp=spp))
        out["seconds"] = time.perf_counter() - start
    else:  # memory of a derivative render, above the compiled scene's footprint
        dr.flush_malloc_cache()
        reset_peak()
        base, gpu_base = rss(), gpu_mb()
        if task == "gradient":
            compiled.render_backward(camera, np.ones((height, width, 3)), ["glass.absorption"], spp=spp)
        else:
            compiled.render_forward(camera, {"glass.absorption": [1.0, 0.0, 0.0]}, spp=spp)
        out["base_mb"], out["peak_mb"] = base, rss()
        if gpu_base is not None:
            out["gpu_growth_mb"] = gpu_mb() - gpu_base
    print(json.dumps(out))
''')


def mitsuba_scene(compiled, view, width, height, ior):
    """Plain Mitsuba's version of a compiled scene seen from ``view``: stock ``dielectric`` glass
    (one IOR: ``ior``, or the green channel's), ``envmap``, ``path`` integrator, tent filter."""
    import mitsuba as mi
    import numpy as np

    d = compiled.mitsuba_dict()
    for name, material in compiled.scene.materials.items():
        if material.type_name == "dielectric":
            value = float(material.ior_rgb[1] if ior is None else ior)
            d[name] = {"type": "dielectric", "int_ior": value, "ext_ior": 1.0, "id": name}
    d["integrator"] = {"type": "path", "max_depth": compiled.scene.render.max_depth}
    R, t, K = (np.asarray(view[k], float) for k in ("R", "t", "K"))
    to_world = np.eye(4)
    to_world[:3, :3] = R.T @ np.diag([-1.0, -1.0, 1.0])  # OpenCV camera axes -> Mitsuba's
    to_world[:3, 3] = -R.T @ t
    d["sensor"] = {"type": "perspective", "fov": float(np.degrees(2 * np.arctan(height / 2 / K[1, 1]))),
                   "fov_axis": "y", "to_world": mi.ScalarTransform4f(to_world),
                   "film": {"type": "hdrfilm", "width": width, "height": height,
                            "rfilter": {"type": "tent"}, "pixel_format": "rgb"}}
    return mi.load_dict(d, optimize=False)


def _child(task: str, scene: Path, width: int, height: int, spp: int) -> dict:
    with tempfile.TemporaryDirectory(prefix="drjit-cache-") as cache:
        env = {**os.environ, "DRJIT_CACHE_DIR": cache}
        result = subprocess.run([sys.executable, "-c", _CHILD, task, str(scene), str(width),
                                 str(height), str(spp), str(Path(__file__).parent)],
                                capture_output=True, text=True, env=env, check=True)
    return json.loads(result.stdout.strip().splitlines()[-1])


def _gpu_name() -> str:
    """The CUDA device's name and driver, as nvidia-smi reports them."""
    out = subprocess.run(["nvidia-smi", "--query-gpu=name,driver_version", "--format=csv,noheader"],
                         capture_output=True, text=True)
    return out.stdout.strip() or "a CUDA device (nvidia-smi did not answer)"


def _time(fn, repeats: int = 3) -> float:
    fn()  # compile
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(min(times))


def measured_material_scene(folder: Path) -> Path:
    """The default scene with the cloth as a ``merl`` table and the backdrop as ``brdf_pca``."""
    import numpy as np

    from abs.brdf.basis import BRDFBasis
    from abs.io.merl import MERL_SHAPE, MERL_SIZE, merl_sample_angles, write_merl

    theta_h = merl_sample_angles()[0]
    lobe = np.exp(-np.square(theta_h / 0.2))  # a glossy highlight over a diffuse base, 1/sr
    table = (np.array([0.18, 0.15, 0.12])[:, None, None, None] / np.pi + 0.5 * lobe[None]).astype(np.float32)
    write_merl(folder / "cloth.binary", table.reshape(MERL_SHAPE))
    rng = np.random.default_rng(0)
    BRDFBasis(mean=np.zeros(MERL_SIZE, np.float32),
              components=(rng.normal(size=(4, MERL_SIZE)) * 0.1).astype(np.float32),
              median=np.full(MERL_SIZE, 0.15, np.float32), epsilon=1e-3).save(folder / "basis.npz")
    text = DEFAULT_SCENE.read_text()
    for asset in ("env.exr", "sphere.ply", "cloth.ply", "backdrop.ply"):
        (folder / asset).write_bytes((DEFAULT_SCENE.parent / asset).read_bytes())
    text = text.replace('type = "diffuse"\nreflectance = [0.8, 0.8, 0.78]   # white cotton, very slightly warm',
                        'type = "merl"\nfile = "cloth.binary"')
    text = text.replace('type = "diffuse"\nreflectance = "checkerboard.png" # sRGB texture: 3 cm squares, grey 0.3 / white 0.8 linear',
                        'type = "brdf_pca"\nbasis = "basis.npz"\ncoefficients = [0.2, -0.1, 0.0, 0.1]')
    assert 'type = "merl"' in text and 'type = "brdf_pca"' in text
    (folder / "scene.toml").write_text(text)
    return folder / "scene.toml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller images and no 256-spp memory row")
    parser.add_argument("--size", default=None, help="WxH of the speed rows (default 200x150; a GPU "
                        "needs larger images to be busy)")
    args = parser.parse_args()

    import drjit as dr
    import mitsuba as mi
    import numpy as np

    from abs.render import Camera, compile_scene
    from abs.render.integrator import PathTracer
    from abs.scene import load_scene
    from abs.simulate import place_cameras

    record: dict = {"variant": None, "machine": platform.machine(), "cpu_count": os.cpu_count()}
    w, h = (100, 75) if args.quick else (200, 150)
    if args.size:
        w, h = (int(v) for v in args.size.lower().split("x"))

    # ---- compile: fresh processes, empty kernel caches
    compile_rows = []
    with tempfile.TemporaryDirectory() as tmp:
        scenes = {"default": DEFAULT_SCENE, "merl+brdf_pca": measured_material_scene(Path(tmp))}
        sizes = [(w, h)] if args.quick else [(w, h), (640, 480)]
        for label, scene in scenes.items():
            for sw, sh in sizes:
                ours = _child("abs_first", scene, sw, sh, 16)["seconds"]
                theirs = _child("mitsuba_first", scene, sw, sh, 16)["seconds"]
                compile_rows.append({"scene": label, "width": sw, "height": sh, "spp": 16,
                                     "abs_first_render_s": ours, "mitsuba_first_render_s": theirs,
                                     "ratio": ours / theirs})
                print(f"compile {label:14s} {sw}x{sh}: abs {ours:6.2f} s, mitsuba {theirs:6.2f} s, "
                      f"ratio {ours / theirs:.2f}", flush=True)
    record["compile"] = compile_rows

    # ---- primal speed, dispersion, derivatives (this process)
    compiled = compile_scene(load_scene(DEFAULT_SCENE))
    record["variant"] = mi.variant()
    view = place_cameras(compiled, 1, w, h)[0]
    camera = Camera(view["K"], view["R"], view["t"], w, h)
    spp = 64
    distinct = compiled.get("glass.ior")
    scalar = float(distinct[1])
    compiled.set("glass.ior", [scalar] * 3)
    mitsuba = mitsuba_scene(compiled, view, w, h, ior=scalar)
    t_abs = _time(lambda: compiled.render(camera, spp=spp).numpy())
    t_mi = _time(lambda: np.array(mi.render(mitsuba, spp=spp)))
    samples = w * h * spp
    record["primal"] = {"width": w, "height": h, "spp": spp, "abs_s": t_abs, "mitsuba_s": t_mi,
                        "abs_samples_per_s": samples / t_abs, "mitsuba_samples_per_s": samples / t_mi,
                        "speed_ratio": t_mi / t_abs}
    print(f"primal {w}x{h} {spp} spp, scalar IOR: abs {t_abs:.3f} s, mitsuba {t_mi:.3f} s, "
          f"samples/s ratio {t_mi / t_abs:.2f}", flush=True)

    # Dispersion: split paths (abs) against one render per channel, at equal noise.
    compiled.set("glass.ior", distinct)
    tracer = PathTracer(max_depth=compiled.scene.render.max_depth)
    scene, env = compiled.mitsuba_scene, compiled.environment

    def per_channel(seed: int) -> np.ndarray:
        image = np.zeros((h, w, 3))
        for c in range(3):
            sampler, ray, _, _, film = tracer._camera_rays(camera, spp, seed * 3 + c)
            ray.time = mi.Float(float(c))  # the whole path carries channel c
            radiance, _ = tracer.trace(scene, env, ray, sampler, split=False)
            dr.eval(radiance)
            image[..., c] = tracer._film(radiance, camera, spp, film).numpy()[..., c]
        return image

    def split(seed: int) -> np.ndarray:
        return tracer.render(scene, env, camera, spp, seed).numpy()

    dispersion = {}
    for label, fn in (("split", split), ("per_channel", per_channel)):
        seconds = _time(lambda: fn(100))
        renders = [fn(s) for s in range(4)]
        variance = float(np.mean(np.var(np.stack(renders), axis=0, ddof=1)))
        dispersion[label] = {"seconds": seconds, "pixel_variance": variance,
                             "efficiency": 1.0 / (variance * seconds)}
    dispersion["split_over_per_channel_efficiency"] = (dispersion["split"]["efficiency"]
                                                       / dispersion["per_channel"]["efficiency"])
    record["dispersion"] = dispersion
    print(f"dispersion: split {dispersion['split']['seconds']:.3f} s var {dispersion['split']['pixel_variance']:.3g}; "
          f"per channel {dispersion['per_channel']['seconds']:.3f} s var {dispersion['per_channel']['pixel_variance']:.3g}; "
          f"efficiency ratio {dispersion['split_over_per_channel_efficiency']:.2f}", flush=True)

    # Derivatives, in primal renders of the same view and spp (distinct IORs: dispersive glass).
    spp_d = 16
    t_primal = _time(lambda: compiled.render(camera, spp=spp_d).numpy())
    # Forward mode proper (differences=False); an IOR's fitted column is central differences
    # (three primal renders by construction), timed beside it.
    column = {"glass.ior": [1.0, 0.0, 0.0], "glass.absorption": [0.0, 0.0, 0.0]}
    t_column = _time(lambda: compiled.render_forward(camera, column, spp=spp_d,
                                                     differences=False)[1].numpy())
    t_difference = _time(lambda: compiled.render_forward(camera, column, spp=spp_d)[1].numpy())
    weights = np.random.default_rng(0).uniform(-1, 1, (h, w, 3))
    t_gradient = _time(lambda: compiled.render_backward(camera, weights, ["glass.absorption",
                                                                          "environment.scale"], spp=spp_d))
    record["derivatives"] = {"width": w, "height": h, "spp": spp_d, "primal_s": t_primal,
                             "jacobian_column_s": t_column, "gradient_s": t_gradient,
                             "jacobian_column_over_primal": t_column / t_primal,
                             "ior_difference_column_over_primal": t_difference / t_primal,
                             "gradient_over_primal": t_gradient / t_primal}
    print(f"derivatives {w}x{h} {spp_d} spp: primal {t_primal:.3f} s, Jacobian column "
          f"{t_column / t_primal:.2f}x, gradient {t_gradient / t_primal:.2f}x", flush=True)

    # ---- memory: fresh processes, 640x480
    memory = []
    for task in ("gradient", "jacobian_column"):
        for n in ((1, 16) if args.quick else (1, 16, 256)):
            m = _child(task, DEFAULT_SCENE, 640, 480, n)
            memory.append({"task": task, "spp": n, "width": 640, "height": 480,
                           "footprint_mb": m["base_mb"], "peak_mb": m["peak_mb"],
                           "growth_mb": m["peak_mb"] - m["base_mb"],
                           "gpu_growth_mb": m.get("gpu_growth_mb")})
            gpu = f", GPU +{m['gpu_growth_mb']:.0f} MB" if "gpu_growth_mb" in m else ""
            print(f"memory {task:15s} 640x480 {n:4d} spp: +{m['peak_mb'] - m['base_mb']:.0f} MB "
                  f"(footprint {m['base_mb']:.0f} MB){gpu}", flush=True)
    record["memory"] = memory
    # On a CUDA variant the loop state lives on the GPU: gpu_growth_mb is the GPU's used memory
    # after the render above its use after compiling the scene (Dr.Jit's allocation cache emptied).
    record["memory_kind"] = ("peak resident memory above the compiled scene's, MB; "
                             "gpu_growth_mb: GPU memory in use after the render above before it")
    record["gpu"] = _gpu_name() if mi.variant().startswith("cuda") else \
        "not measured: no CUDA device was available to this run"

    out = ROOT / "benchmarks/results"
    out.mkdir(parents=True, exist_ok=True)
    name = "render_speed" + ("_cuda" if mi.variant().startswith("cuda") else "") \
        + ("_quick" if args.quick else "") + ".json"
    (out / name).write_text(json.dumps(record, indent=2))
    print(f"saved {out / name}\n")
    print("\n".join(markdown_table(record)))


def markdown_table(record: dict) -> list[str]:
    """The README's table: every target of the renderer with the ratio this run measured."""
    rows = ["| what | target | measured (abs / Mitsuba `path`, same run) |", "|---|---|---|"]
    for r in record["compile"]:
        rows.append(f"| first render, {r['scene']} scene, {r['width']}x{r['height']} | <= 3x | "
                    f"{r['ratio']:.2f}x ({r['abs_first_render_s']:.2f} s / {r['mitsuba_first_render_s']:.2f} s) |")
    p = record["primal"]
    rows.append(f"| samples per second, scalar IOR, {p['width']}x{p['height']} {p['spp']} spp | >= 0.8x | "
                f"{p['speed_ratio']:.2f}x ({p['abs_samples_per_s'] / 1e6:.2f} / {p['mitsuba_samples_per_s'] / 1e6:.2f} M/s) |")
    d = record["dispersion"]
    rows.append(f"| per-channel IOR: split paths vs one render per channel, efficiency at equal noise | > 1x | "
                f"{d['split_over_per_channel_efficiency']:.2f}x |")
    g = record["derivatives"]
    rows.append(f"| Jacobian column (forward mode) / primal render | <= 2.5x | {g['jacobian_column_over_primal']:.2f}x |")
    rows.append(f"| gradient (path replay) / primal render | <= 2.5x | {g['gradient_over_primal']:.2f}x |")
    for task in ("gradient", "jacobian_column"):
        m = {r["spp"]: r for r in record["memory"] if r["task"] == task}
        cells = ", ".join(f"{n} spp +{m[n]['growth_mb']:.0f} MB" for n in sorted(m))
        rows.append(f"| memory of a {task.replace('_', ' ')}, 640x480 | flat in spp | {cells} |")
        if all(m[n].get("gpu_growth_mb") is not None for n in m):
            cells = ", ".join(f"{n} spp +{m[n]['gpu_growth_mb']:.0f} MB" for n in sorted(m))
            rows.append(f"| GPU memory of a {task.replace('_', ' ')}, 640x480 | flat in spp | {cells} |")
    return rows


if __name__ == "__main__":
    main()
