#!/usr/bin/env python3
"""Lamina against its peers on real meshes, in one command.

Times Lamina and, where they are installed, its peers on the same models and the same
work, and prints a table of times, ratios and peak memory (also written to a file):

- slicing (load + slice + loops + hierarchy at 0.2 mm): trimesh `section_multiplane`,
  manifold3d `slice`;
- offsets (10 inward offsets 0.4 mm apart on every layer of 3DBenchy): pyclipr
  (Clipper2);
- signed distance field (512 x 512 grid, 10 iso-levels per layer): scipy
  `distance_transform_edt` + scikit-image `find_contours`;
- STL to G-code: `prusa-slicer --export-gcode` (0.2 mm, 3 perimeters, 20 % infill),
  when Lamina has a `gcode` exporter;
- print economy (`--only economy`): for the gear on the mixing head, the two-tool
  3DBenchy on `marlin-toolchanger-2` and the turbine blade on the mixing head, the file's
  own time (every wait included), its deposited part volume, waste share and retraction
  count, read back by tests/replay/gcode_replay.py, next to PrusaSlicer's file for the
  same mesh at 100 % infill, the same layer height and speeds (../shared/REFERENCES.md).

Every figure is the median of several runs after a warm-up, each run a fresh process
(in a quick run, a warm-up of 2 s or more is the figure's one run):
its whole-process wall time and peak RSS (from wait4), plus the time the work itself
took inside the process (Lamina's `--timings`, the peers' own clock around the call).
Both sides run in the same invocation, one after the other.

Usage: python3 benches/benchsuite.py [--quick] [--runs N] [--models DIR]
       [--lamina PATH] [--python PATH] [--out FILE]
See benches/README.md for installing the peers.
"""

import argparse
import datetime
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# (file, scale to mm, label)
SLICE_MODELS = [
    ("3DBenchy.stl", 1.0, "3DBenchy"),
    ("turbine_blade_vtk.stl", 1.0, "turbine blade"),
    ("stanford_bunny.stl", 1000.0, "bunny x1000"),
    ("openfoam_buildings_400k.stl", 1.0, "buildings 400k"),
]


# `--allow` for the models folder: pipelines read files outside their own folder only
# when the command line allows it (set in main).
ALLOW = []


def peer_slice(modules):
    """The start of a slicing peer's script: imports numpy, trimesh and ``modules``
    (", name, ..."), then loads the mesh argv[1] scaled by argv[2] into ``m``, timed
    from ``t0`` to ``t1`` (wall) and ``c0`` to ``c1`` (CPU of the process, all its
    threads); argv[3] is the layer height ``step``."""
    return r"""
import sys, time, json
import numpy as np, trimesh""" + modules + r"""
path, scale, step = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
t0, c0 = time.perf_counter(), time.process_time()
m = trimesh.load(path, force="mesh")
m.apply_scale(scale)
t1, c1 = time.perf_counter(), time.process_time()
"""


PEER_SLICE_TRIMESH = peer_slice("") + r"""z0, z1 = m.bounds[0][2], m.bounds[1][2]
heights = np.arange(step / 2, z1 - z0, step)
sections = m.section_multiplane(plane_origin=[0, 0, z0], plane_normal=[0, 0, 1], heights=heights)
loops = sum(len(s.polygons_full) for s in sections if s is not None)
t2, c2 = time.perf_counter(), time.process_time()
print(json.dumps({"work": t2 - t0, "cpu": c2 - c0, "load": t1 - t0, "slice": t2 - t1, "layers": len(heights),
                  "loops": loops}))
"""

PEER_SLICE_MANIFOLD = peer_slice(", manifold3d") + r"""mesh = manifold3d.Mesh(vert_properties=np.asarray(m.vertices, dtype=np.float32),
                       tri_verts=np.asarray(m.faces, dtype=np.uint32))
man = manifold3d.Manifold(mesh)
z0, z1 = m.bounds[0][2], m.bounds[1][2]
loops = 0
layers = 0
z = z0 + step / 2
while z < z1:
    loops += len(man.slice(z).to_polygons())
    layers += 1
    z += step
t2, c2 = time.perf_counter(), time.process_time()
print(json.dumps({"work": t2 - t1, "cpu": c2 - c1, "load": t1 - t0, "layers": layers, "loops": loops,
                  "status": str(man.status())}))
"""

PEER_OFFSET_PYCLIPR = r"""
import sys, time, json
import numpy as np, pyclipr
layers = json.load(open(sys.argv[1]))
count, step = int(sys.argv[2]), float(sys.argv[3])
paths = [[np.asarray(c, dtype=float) for c in layer] for layer in layers]
t0 = time.perf_counter()
total = 0
for layer in paths:
    for k in range(1, count + 1):
        po = pyclipr.ClipperOffset()
        po.scaleFactor = 1000
        po.addPaths(layer, pyclipr.JoinType.Round, pyclipr.EndType.Polygon)
        total += len(po.execute(-step * k))
t1 = time.perf_counter()
print(json.dumps({"work": t1 - t0, "layers": len(paths), "paths": total}))
"""

# argv[1]: layers, each a list of families, each a list of rings. argv[4] says what one
# field covers:
# - "family": the same work as Lamina's `distance-field` stage, one field per family
#   (an outer contour and its holes) over the family's own box padded by 1.5 samples,
#   with argv[2] samples along its longer side (Lamina's `Field::over`);
# - "layer": one square field per layer over the layer's box, argv[2] samples a side:
#   fewer fields than Lamina on layers of several families (3DBenchy: 2.45 a layer).
# Only the field and the contours at argv[3] levels are timed.
PEER_SDF_SCIPY = r"""
import sys, time, json, math
import numpy as np
from scipy import ndimage
from skimage import draw, measure
layers = json.load(open(sys.argv[1]))
cells, levels, per = int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]

def grid(rings):
    # (origin, sample spacing, columns, rows) of the field over `rings`.
    pts = np.concatenate(rings)
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    if per == "layer":
        size = (hi - lo).max() * 1.02 + 1e-9
        return lo, size / (cells - 1), cells, cells
    h = max((hi - lo).max(), 1e-300) / (cells - 3.0)
    nx = max(math.ceil((hi[0] - lo[0]) / h) + 4, 4)
    ny = max(math.ceil((hi[1] - lo[1]) / h) + 4, 4)
    return lo - 1.5 * h, h, nx, ny

edt = contours = 0.0
fields = 0
for layer in layers:
    families = [[np.asarray(c, dtype=float) for c in family] for family in layer]
    groups = [[c for family in families for c in family]] if per == "layer" else families
    for rings in groups:
        origin, h, nx, ny = grid(rings)
        mask = np.zeros((ny, nx), dtype=bool)
        for c in rings:
            q = (c - origin) / h
            rr, cc = draw.polygon(q[:, 1], q[:, 0], (ny, nx))
            mask[rr, cc] ^= True
        t0 = time.perf_counter()
        d = ndimage.distance_transform_edt(mask) - ndimage.distance_transform_edt(~mask)
        t1 = time.perf_counter()
        top = d.max()
        for k in range(levels):
            measure.find_contours(d, top * k / levels)
        t2 = time.perf_counter()
        edt += t1 - t0
        contours += t2 - t1
        fields += 1
print(json.dumps({"work": edt + contours, "edt": edt, "contours": contours, "layers": len(layers),
                  "fields": fields}))
"""


def run_process(cmd, cwd=None):
    """Runs a command; returns (wall seconds, stdout, stderr, exit code)."""
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    out, err = proc.communicate()
    wall = time.perf_counter() - start
    return wall, out.decode(errors="replace"), err.decode(errors="replace"), proc.returncode


# RUSAGE_CHILDREN keeps the maximum over all children a process ever had, so every
# measurement runs in a fresh measuring process whose only child is the command.
MEASURE = r"""
import sys, time, json, subprocess
start = time.perf_counter()
proc = subprocess.Popen(sys.argv[1:], stdout=subprocess.PIPE, stderr=subprocess.PIPE)
out, err = proc.communicate()
wall = time.perf_counter() - start
import resource
# The only child of this process: its peak RSS.
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
sys.stdout.write(json.dumps({"wall": wall, "rss_kib": usage.ru_maxrss, "cpu": usage.ru_utime + usage.ru_stime,
                             "code": proc.returncode,
                             "out": out.decode(errors="replace"), "err": err.decode(errors="replace")}))
"""


def measure(cmd, cwd=None):
    """Runs `cmd` in a fresh measuring process: whole-process wall time, peak RSS (MiB),
    stdout; raises on failure."""
    r = measure_all(cmd, cwd)
    return r["wall"], r["rss"], r["out"]


def measure_all(cmd, cwd=None):
    """`measure` with the process's CPU time (user + system, all threads) as well: a
    dict of wall, cpu, rss (MiB) and out."""
    wall, out, err, code = run_process([sys.executable, "-c", MEASURE] + [str(c) for c in cmd], cwd=cwd)
    if code != 0:
        raise RuntimeError(f"measuring {Path(str(cmd[0])).name} failed: {err.strip()[-300:]}")
    r = json.loads(out)
    if r["code"] != 0:
        lines = [l.strip() for l in r["err"].splitlines() if l.strip()]
        first = next((l for l in lines if l.startswith("error")), lines[-1] if lines else "no message")
        raise RuntimeError(f"{Path(str(cmd[0])).name} exited {r['code']}: {first}")
    return {"wall": r["wall"], "cpu": r["cpu"], "rss": r["rss_kib"] / 1024.0, "out": r["out"]}


def repeat(cmd, runs, cwd=None):
    """Median wall, median peak RSS and the stdout of each run, after one warm-up."""
    r = repeat_all(cmd, runs, cwd)
    return r["wall"], r["rss"], r["outs"]


# In a quick run (one run per figure), a warm-up that takes at least this long (s) is
# the run: what a first run pays beyond the next (the page cache, Python's compiled
# imports, both already warm from the checks before it) is a small share of it, and a
# second run would double the suite's time for its longest figures. None: always warm up.
WARM_UP_IS_THE_RUN_FROM = None


def repeat_all(cmd, runs, cwd=None):
    """Medians of wall, CPU and peak RSS over `runs` runs after one warm-up, and the
    stdout of each run."""
    warm = measure_all(cmd, cwd)
    if runs == 1 and WARM_UP_IS_THE_RUN_FROM is not None and warm["wall"] >= WARM_UP_IS_THE_RUN_FROM:
        return {"wall": warm["wall"], "cpu": warm["cpu"], "rss": warm["rss"], "outs": [warm["out"]]}
    got = [measure_all(cmd, cwd) for _ in range(runs)]
    return {"wall": statistics.median(g["wall"] for g in got), "cpu": statistics.median(g["cpu"] for g in got),
            "rss": statistics.median(g["rss"] for g in got), "outs": [g["out"] for g in got]}


def lamina_timings(out):
    """Per-stage times from `lamina run --timings`."""
    t = {}
    for line in out.splitlines():
        parts = line.split()
        if len(parts) == 2:
            try:
                t[parts[0]] = float(parts[1])
            except ValueError:
                pass
    return t


def median_of(outs, key):
    vals = []
    for o in outs:
        try:
            vals.append(json.loads(o.strip().splitlines()[-1])[key])
        except (ValueError, IndexError, KeyError):
            pass
    return statistics.median(vals) if vals else float("nan")


def peer_available(python, modules):
    code = "import " + ", ".join(modules)
    return subprocess.run([python, "-c", code], capture_output=True).returncode == 0


def write_pipeline(dir_, name, text):
    path = Path(dir_) / f"{name}.toml"
    path.write_text(text)
    return path


def model_table(path, scale):
    return f'[model]\nuse = "stl"\nfile = "{path}"\nscale = {scale}\n[materials.a]\ncolour = [200, 60, 60]\n'


def graded_growth(job, base, subdivided, benchy, runs, work, row, notes):
    """The graded job's growth (targets of the speed work): 3DBenchy subdivided x4 and
    x16 (the same surface in more triangles: <= 1.5x and <= 3x the x1 wall time), and
    four times the layers (0.05 mm: <= 4.4x). At 0.05 mm a level of the default wipe
    tower cannot take a tool change's purge, so that run has a deeper tower."""
    for label, mesh in subdivided.items():
        try:
            r = repeat_all(job[:-2] + ["--set", f'model.file="{mesh}"'], runs)
            row(f"graded job, 3DBenchy {label}", "lamina", r["wall"], r["rss"], r["wall"],
                detail=f"whole process, CPU {r['cpu']:.2f} s, {r['wall'] / base:.2f}x the x1 job "
                       f"(target <= {'1.5' if label == 'x4' else '3'}x)")
        except RuntimeError as e:
            notes.append(f"lamina graded job on 3DBenchy {label}: {e}")
    text = (ROOT / "pipelines" / "benchy-two-tools.toml").read_text()
    text = text.replace('machine = "marlin-toolchanger-2"',
                        'machine = { base = "marlin-toolchanger-2", wipe_tower = { size = [60.0, 40.0] } }')
    text = text.replace("thickness = 0.2", "thickness = 0.05")
    text = text.replace('file = "../../shared/models/3DBenchy.stl"', f'file = "{benchy}"')
    pipe = write_pipeline(work, "graded-thin", text)
    try:
        r = repeat_all([job[0], "run", *ALLOW, "--quiet", "--out", work / "graded-thin", pipe], runs)
        row("graded job, 0.05 mm layers", "lamina", r["wall"], r["rss"], r["wall"],
            detail=f"whole process, CPU {r['cpu']:.2f} s, {r['wall'] / base:.2f}x the 0.2 mm job (target <= 4.4x)")
    except RuntimeError as e:
        notes.append(f"lamina graded job at 0.05 mm: {e}")


# PrusaSlicer at full density, 0.2 mm layers, 30 mm/s and 120 mm/s travel: the machine
# time and material a single-material print of the same mesh takes.
PRUSA_FULL = ["--export-gcode", "--layer-height", "0.2", "--first-layer-height", "0.2",
              "--nozzle-diameter", "0.4", "--fill-density", "100%", "--fill-pattern", "rectilinear",
              "--perimeter-speed", "30", "--external-perimeter-speed", "30", "--infill-speed", "30",
              "--solid-infill-speed", "30", "--top-solid-infill-speed", "30", "--gap-fill-speed", "30",
              "--small-perimeter-speed", "30", "--bridge-speed", "30", "--first-layer-speed", "25",
              "--travel-speed", "120"]

# What a file deposits besides the part, by its `;TYPE:` labels as the replay keys them
# (the first word, in capitals): Lamina's, and PrusaSlicer's skirt, wipe tower and the
# start code's purge line (`Custom`).
WASTE_TYPES = {"PRIME", "PURGE", "TOWER", "SKIRT", "SKIRT/BRIM", "WIPE", "CUSTOM"}


def file_time(gcode):
    """The file's own time estimate in seconds: Lamina's footer or PrusaSlicer's
    `estimated printing time (normal mode) = 1h 2m 3s`."""
    for line in reversed(Path(gcode).read_text(errors="replace").splitlines()[-400:]):
        if "estimated printing time" not in line:
            continue
        text = line.split("=", 1)[1] if "=" in line else line.split(":", 1)[1]
        if text.strip().endswith(" s") and "h" not in text and "m" not in text:
            return float(text.strip()[:-2])
        total = 0.0
        for part in text.split():
            for unit, scale in (("d", 86400), ("h", 3600), ("m", 60), ("s", 1)):
                if part.endswith(unit) and part[:-1].replace(".", "").isdigit():
                    total += float(part[:-1]) * scale
        return total
    return None


def retractions(gcode):
    """Moves that only pull filament back (G1 E- without X or Y), following M82/M83
    and G92."""
    e, relative, n = 0.0, False, 0
    for line in Path(gcode).read_text(errors="replace").splitlines():
        words = line.split(";")[0].split()
        if not words:
            continue
        cmd, args = words[0].upper(), {w[0].upper(): w[1:] for w in words[1:] if w}
        if cmd == "M83":
            relative = True
        elif cmd == "M82":
            relative = False
        elif cmd == "G92" and "E" in args:
            e = float(args["E"])
        elif cmd in ("G0", "G1") and "E" in args:
            v = float(args["E"])
            de = v if relative else v - e
            e = e + de if relative else v
            if de < 0 and "X" not in args and "Y" not in args:
                n += 1
    return n


def economy_of(gcode, python):
    """(file time s, part mm³, waste share, retractions) of a G-code file, its volumes
    read back by the replay checker."""
    report = Path(str(gcode) + ".replay.json")
    subprocess.run([python, ROOT / "tests" / "replay" / "gcode_replay.py", gcode, "--json", report],
                   capture_output=True, text=True)
    volumes = json.loads(report.read_text())["volume"]["by_type_mm3"]
    total = sum(volumes.values())
    waste = sum(v for k, v in volumes.items() if k in WASTE_TYPES)
    return file_time(gcode), total - waste, (waste / total if total else 0.0), retractions(gcode)


def economy(lamina, models, work, python, notes):
    """The economy table's rows: each job's Lamina file and PrusaSlicer's for the same
    mesh, side by side."""
    rows = []
    gear = work / "gear.stl"
    subprocess.run([lamina, "generate", "gear", "teeth=16", "height=5", "-o", gear], check=True,
                   capture_output=True)
    jobs = [
        ("gear on the mixing head", ROOT / "pipelines" / "gear-mixing-gcode.toml", [], gear,
         ["--retract-length", "4"]),
        ("two-tool 3DBenchy, marlin-toolchanger-2", ROOT / "pipelines" / "benchy-two-tools.toml",
         ["--model", models / "3DBenchy.stl"], models / "3DBenchy.stl", []),
        ("turbine blade on the mixing head", ROOT / "pipelines" / "gear-mixing-gcode.toml",
         ["--model", models / "turbine_blade_vtk.stl"], models / "turbine_blade_vtk.stl", ["--retract-length", "4"]),
    ]
    for label, pipeline, extra, mesh, prusa_extra in jobs:
        if not Path(mesh).exists():
            notes.append(f"economy, {label}: {mesh} absent, skipped")
            continue
        out = work / "economy" / label.split()[0]
        r = subprocess.run([lamina, "run", *ALLOW, "--quiet", "--out", out, pipeline, *extra], capture_output=True, text=True)
        files = sorted(out.glob("*.gcode"))
        if r.returncode != 0 or not files:
            notes.append(f"economy, {label}: lamina failed: {r.stderr.strip()[-200:]}")
            continue
        ours = economy_of(files[0], python)
        rows.append((label, "lamina", *ours))
        if shutil.which("prusa-slicer"):
            theirs_file = work / "economy" / (label.split()[0] + "-prusa.gcode")
            p = subprocess.run(["prusa-slicer", *PRUSA_FULL, *prusa_extra, "--output", theirs_file, mesh],
                               capture_output=True, text=True)
            if p.returncode == 0:
                rows.append((label, "prusa-slicer", *economy_of(theirs_file, python)))
            else:
                notes.append(f"economy, {label}: prusa-slicer failed: {p.stderr.strip()[-200:]}")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer models and runs (under 2 minutes)")
    ap.add_argument("--runs", type=int, default=None, help="runs per figure after the warm-up (default 5; quick 1)")
    ap.add_argument("--models", default=os.environ.get("LAMINA_MODELS", str(ROOT.parent / "shared" / "models")))
    ap.add_argument("--lamina", default=str(ROOT / "target" / "release" / "lamina"))
    ap.add_argument("--python", default=sys.executable, help="interpreter that has the Python peers")
    ap.add_argument("--out", default=None, help="where to write the table (default target/benchsuite/...)")
    ap.add_argument("--only", action="append", choices=["slice", "offset", "sdf", "gcode", "economy"],
                    help="run only these tasks (repeatable; default all)")
    args = ap.parse_args()
    runs = args.runs or (1 if args.quick else 5)
    if args.quick:
        global WARM_UP_IS_THE_RUN_FROM
        WARM_UP_IS_THE_RUN_FROM = 2.0
    # Absolute: the pipelines it writes live in a temporary folder, where a relative
    # path (CI's `../shared/models`) would name nothing.
    models = Path(args.models).resolve()
    ALLOW[:] = ["--allow", str(models)]
    if not models.is_dir():
        print(f"note: {models} not found; nothing to measure")
        return 0
    lamina = Path(args.lamina)
    if not lamina.exists():
        print("building lamina (release)...", flush=True)
        subprocess.run(["cargo", "build", "--release", "--locked", "--bin", "lamina"], cwd=ROOT, check=True)
    has = {
        "trimesh": peer_available(args.python, ["trimesh", "numpy", "rtree", "shapely"]),
        "manifold3d": peer_available(args.python, ["manifold3d", "trimesh"]),
        "pyclipr": peer_available(args.python, ["pyclipr", "numpy"]),
        "scipy": peer_available(args.python, ["scipy", "skimage", "numpy"]),
        "prusa-slicer": shutil.which("prusa-slicer") is not None,
    }
    rows = []
    notes = [f"peers found: {', '.join(k for k, v in has.items() if v) or 'none'}"]
    tmp = tempfile.TemporaryDirectory(prefix="lamina-benchsuite-")
    work = Path(tmp.name)

    def row(task, tool, wall, rss, inside, base=None, detail=""):
        rows.append({"task": task, "tool": tool, "wall": wall, "rss": rss, "inside": inside,
                     "ratio": (inside / base) if base else None, "detail": detail})
        ratio = f"{inside / base:.1f}x" if base else ""
        print(f"  {task:<28} {tool:<14} wall {wall:7.3f} s  work {inside:7.3f} s  {rss:7.1f} MiB  {ratio} {detail}",
              flush=True)

    # The economy table slices three jobs twice over: not part of a quick run.
    tasks = set(args.only or ["slice", "offset", "sdf", "gcode"] + ([] if args.quick else ["economy"]))

    # --- slicing -------------------------------------------------------------------
    slice_models = [] if "slice" not in tasks else SLICE_MODELS[:2] if args.quick else SLICE_MODELS
    # 3DBenchy subdivided once (x4 triangles) and twice (x16, 3.6M): the same surface
    # in more triangles, for slicing and for the graded job's growth.
    subdivided = {}
    if not args.quick and has["trimesh"] and (models / "3DBenchy.stl").exists() and tasks & {"slice", "gcode"}:
        code = ("import sys, trimesh; m = trimesh.load(sys.argv[1], force='mesh'); "
                "m4 = m.subdivide(); m4.export(sys.argv[2]); m4.subdivide().export(sys.argv[3])")
        x4, x16 = work / "benchy_x4.stl", work / "benchy_x16.stl"
        if subprocess.run([args.python, "-c", code, str(models / "3DBenchy.stl"), str(x4), str(x16)]).returncode == 0:
            subdivided = {"x4": x4, "x16": x16}
    extra = []
    if "x16" in subdivided and "slice" in tasks:
        extra.append((str(subdivided["x16"]), 1.0, "3DBenchy x16 (3.6M)"))
    print("slicing at 0.2 mm (load + slice + loops + hierarchy)", flush=True)
    for file, scale, label in [(str(models / f), s, l) for f, s, l in slice_models] + extra:
        if not Path(file).exists():
            notes.append(f"{label}: {file} absent, skipped")
            continue
        pipe = write_pipeline(work, "slice", model_table(file, scale) + '[slice]\nuse = "uniform"\nthickness = 0.2\n')
        wall, rss, outs = repeat([lamina, "run", *ALLOW, "--quiet", "--timings", "--out", work / "out", pipe], runs)
        stages = [lamina_timings(o) for o in outs]
        inside = statistics.median(s.get("model", 0) + s.get("slice", 0) + s.get("sort", 0) for s in stages)
        base = inside
        row(f"slice {label}", "lamina", wall, rss, inside,
            detail="stage sums: " + ", ".join(f"{k} {statistics.median(s.get(k, 0) for s in stages):.3f}"
                                              for k in ("model", "slice", "sort")))
        for peer, script, mods in (("trimesh", PEER_SLICE_TRIMESH, "trimesh"),
                                   ("manifold3d", PEER_SLICE_MANIFOLD, "manifold3d")):
            if not has[mods]:
                continue
            try:
                w, m, o = repeat([args.python, "-c", script, file, scale, 0.2], runs)
                # Lamina's work is its stages' time summed over threads, which is CPU
                # time; the peer's is wall time inside the process, and manifold3d
                # builds on several threads: its CPU time is given beside it.
                cpu = median_of(o, "cpu")
                detail = f"{median_of(o, 'loops'):.0f} loops, CPU {cpu:.4f} s ({cpu / base:.1f}x)"
                try:
                    status = json.loads(o[-1].strip().splitlines()[-1]).get("status")
                except (ValueError, IndexError):
                    status = None
                if status and not status.endswith("NoError"):
                    # manifold3d refuses meshes that are not closed manifolds and slices
                    # an empty solid instead: its time is then no comparison.
                    detail += f", mesh refused: {status}"
                row(f"slice {label}", peer, w, m, median_of(o, "work"), base, detail=detail)
            except RuntimeError as e:
                notes.append(f"{peer} on {label}: {e}")

    # --- offsets and distance fields on 3DBenchy -------------------------------------
    benchy = models / "3DBenchy.stl"
    # Quick runs take every fifth layer's height (1 mm) for offsets and distance fields.
    thickness = 1.0 if args.quick else 0.2
    if benchy.exists():
        layers_json = work / "benchy_layers.json"
        pipe = write_pipeline(work, "contours", model_table(benchy, 1.0)
                              + f'[slice]\nuse = "uniform"\nthickness = {thickness}\n'
                              + '[[output]]\nuse = "json"\npath = "plan.json"\n')
        subprocess.run([lamina, "run", *ALLOW, "--quiet", "--out", work / "contours", pipe], check=True)
        plan = json.loads((work / "contours" / "plan.json").read_text())
        layers = []
        # The same rings grouped by family, for the peer that makes a field per family.
        families = []
        for layer in plan["layers"]:
            rings = []
            fams = []
            for part in layer["parts"]:
                for fam in part["families"]:
                    rings.append(fam["outer"])
                    rings.extend(fam["holes"])
                    fams.append([fam["outer"]] + fam["holes"])
            if rings:
                layers.append(rings)
                families.append(fams)
        layers_json.write_text(json.dumps(layers))
        families_json = work / "benchy_families.json"
        families_json.write_text(json.dumps(families))
        n_layers = len(layers)

        if "offset" in tasks:
            print(f"offsets: 10 inward offsets 0.4 mm apart on every 3DBenchy layer ({n_layers} layers)", flush=True)
            pipe = write_pipeline(work, "offset", model_table(benchy, 1.0)
                                  + f'[slice]\nuse = "uniform"\nthickness = {thickness}\n'
                                  + '[discretise]\nuse = "offset"\ncount = 10\nspacing = 0.4\n')
            wall, rss, outs = repeat([lamina, "run", *ALLOW, "--quiet", "--timings", "--out", work / "out", pipe], runs)
            # The whole job's wall time against the peer's offsets alone.
            inside = wall
            stage = statistics.median(lamina_timings(o).get("discretise", float("nan")) for o in outs)
            row(f"offset 3DBenchy ({n_layers} layers)", "lamina", wall, rss, inside,
                detail=f"whole job; discretise {stage:.3f} s summed over threads")
            if has["pyclipr"]:
                w, m, o = repeat([args.python, "-c", PEER_OFFSET_PYCLIPR, layers_json, 10, 0.4], runs)
                row(f"offset 3DBenchy ({n_layers} layers)", "pyclipr", w, m, median_of(o, "work"), inside,
                    detail="offsets only")

        if "sdf" in tasks:
            print("signed distance field 512 x 512, 10 iso-levels, per layer", flush=True)
            pipe = write_pipeline(work, "sdf", model_table(benchy, 1.0)
                                  + f'[slice]\nuse = "uniform"\nthickness = {thickness}\n'
                                  + '[discretise]\nuse = "distance-field"\ncells = 512\ncount = 10\n')
            wall, rss, outs = repeat([lamina, "run", *ALLOW, "--quiet", "--timings", "--threads", "1", "--out",
                                      work / "out", pipe], runs)
            # The `distance-field` stage as a whole: field, iso-lines, bands and regions.
            per_layer = statistics.median(lamina_timings(o).get("discretise", float("nan")) for o in outs) / n_layers
            row("SDF per layer (1 thread)", "lamina", wall, rss, per_layer,
                detail=f"the whole distance-field stage, {n_layers} layers; target <= 0.12 x the per-family peer")
            if has["scipy"]:
                for per, label, what in [("layer", "scipy+skimage", "one field per layer"),
                                         ("family", "scipy+skimage per family", "one field per family as Lamina")]:
                    w, m, o = repeat([args.python, "-c", PEER_SDF_SCIPY, families_json, 512, 10, per], runs)
                    done = median_of(o, "layers")
                    row("SDF per layer (1 thread)", label, w, m, median_of(o, "work") / done, per_layer,
                        detail=f"{what} ({median_of(o, 'fields'):.0f} fields"
                               + ("; target: the peer >= 8.3x Lamina" if per == "family" else "") + "); "
                               f"edt {median_of(o, 'edt') / done * 1e3:.1f} ms + contours "
                               f"{median_of(o, 'contours') / done * 1e3:.1f} ms")

        # --- STL to G-code ----------------------------------------------------------------
        if "gcode" in tasks:
            listed = subprocess.run([lamina, "plugins", "export", "--json"], capture_output=True, text=True)
            has_gcode = '"gcode"' in listed.stdout
            if has_gcode:
                print("STL to G-code on 3DBenchy at 0.2 mm", flush=True)
                pipe = write_pipeline(work, "gcode", model_table(benchy, 1.0)
                                      + '[slice]\nuse = "uniform"\nthickness = 0.2\n'
                                      + '[discretise]\nuse = "offset"\ncount = 3\nspacing = 0.45\n'
                                      + '[plan]\nuse = "sequential"\n'
                                      + '[[output]]\nuse = "gcode"\npath = "benchy.gcode"\n')
                try:
                    wall, rss, outs = repeat([lamina, "run", *ALLOW, "--quiet", "--timings", "--out", work / "out", pipe], runs)
                    base = wall
                    row("G-code 3DBenchy", "lamina", wall, rss, wall, detail="whole process")
                except RuntimeError as e:
                    base = None
                    notes.append(f"lamina G-code: {e}")
            else:
                base = None
                notes.append("lamina has no gcode exporter yet: G-code comparison skipped")
            # The graded two-tool job a user runs (pipelines/benchy-two-tools.toml: offset
            # sub-regions, Z and X-Y grading, concurrent plan, G-code), whole process, at
            # one thread and at every core.
            graded = None
            if has_gcode:
                print("graded two-tool 3DBenchy job (pipelines/benchy-two-tools.toml)", flush=True)
                job = [lamina, "run", *ALLOW, "--quiet", "--out", work / "graded", ROOT / "pipelines" / "benchy-two-tools.toml",
                       "--set", f'model.file="{benchy}"']
                try:
                    one = repeat_all(job[:2] + ["--threads", "1"] + job[2:], runs)
                    every = repeat_all(job, runs)
                    graded = every["wall"]
                    cores = os.cpu_count() or 1
                    row("graded two-tool 3DBenchy", "lamina 1 thread", one["wall"], one["rss"], one["wall"],
                        detail=f"whole process, CPU {one['cpu']:.2f} s")
                    row("graded two-tool 3DBenchy", f"lamina {cores} threads", every["wall"], every["rss"],
                        every["wall"], detail=f"whole process, CPU {every['cpu']:.2f} s, "
                                              f"{one['wall'] / every['wall']:.2f}x the 1-thread speed")
                except RuntimeError as e:
                    notes.append(f"lamina graded job: {e}")
                if graded:
                    graded_growth(job, graded, subdivided, benchy, runs, work, row, notes)
            if has["prusa-slicer"] and (base or graded):
                cmd = ["prusa-slicer", "--export-gcode", "--layer-height", "0.2", "--perimeters", "3",
                       "--fill-density", "20%", "--output", work / "prusa.gcode", benchy]
                try:
                    r = repeat_all(cmd, runs)
                    w, m = r["wall"], r["rss"]
                    if base:
                        row("G-code 3DBenchy", "prusa-slicer", w, m, w, base, detail="whole process")
                    if graded:
                        row("graded two-tool 3DBenchy", "prusa-slicer", w, m, w, graded,
                            detail=f"its plain job, whole process, CPU {r['cpu']:.2f} s; "
                                   f"target: lamina <= 0.2x, a ratio >= 5x")
                except RuntimeError as e:
                    notes.append(f"prusa-slicer: {e}")
    else:
        notes.append("3DBenchy absent: offsets, distance fields and G-code skipped")

    # --- print economy ---------------------------------------------------------------------
    economy_rows = []
    if "economy" in tasks:
        print("print economy: file time, part volume, waste, retractions", flush=True)
        economy_rows = economy(lamina, models, work, args.python, notes)

    # --- report -------------------------------------------------------------------------
    stamp = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    warm = "after a warm-up" if WARM_UP_IS_THE_RUN_FROM is None else \
        f"after a warm-up, or the warm-up itself when it took {WARM_UP_IS_THE_RUN_FROM:g} s or more"
    lines = [f"# Lamina benchsuite ({'quick, ' if args.quick else ''}median of {runs} run(s) {warm}, {stamp})",
             "", f"machine: {os.cpu_count()} cores; work = time inside the process for the measured task;",
             "ratio = peer work / Lamina work (above 1: Lamina is faster).", "",
             "| task | tool | wall s | work s | peak RSS MiB | ratio | detail |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        ratio = f"{r['ratio']:.1f}x" if r["ratio"] else ""
        lines.append(f"| {r['task']} | {r['tool']} | {r['wall']:.3f} | {r['inside']:.4f} | {r['rss']:.1f} | "
                     f"{ratio} | {r['detail']} |")
    if economy_rows:
        lines += ["", "Print economy (the file's own time with every wait, part volume and waste from the replay's "
                  ";TYPE: volumes, retractions; PrusaSlicer at 100 % infill, same layer height and speeds):", "",
                  "| job | tool | file time s | part mm³ | waste share | retractions | time vs PrusaSlicer |",
                  "|---|---|---|---|---|---|---|"]
        peers = {r[0]: r for r in economy_rows if r[1] == "prusa-slicer"}
        for job, tool, t, part, waste, retracts in economy_rows:
            ratio = f"{t / peers[job][2]:.3f}x" if tool == "lamina" and job in peers and t and peers[job][2] else ""
            lines.append(f"| {job} | {tool} | {t:.1f} | {part:.1f} | {waste:.4f} | {retracts} | {ratio} |")
    lines += [""] + [f"- {n}" for n in notes]
    text = "\n".join(lines) + "\n"
    print()
    print(text)
    out = Path(args.out) if args.out else ROOT / "target" / "benchsuite" / \
        f"benchsuite-{datetime.datetime.now().strftime('%Y%m%d-%H%M%S')}.md"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"written to {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
