#!/usr/bin/env python3
"""Every mesh of a folder through Lamina's G-code pipelines: is the part made?

For each mesh (``*.stl``) and each pipeline (default: ``gear-mixing-gcode`` and
``benchy-two-tools``), runs ``lamina run PIPELINE --model MESH`` as a user would and
sorts the outcome into one of three:

- ``ok``: the run exits 0 and its G-code deposits, as tests/replay/gcode_replay.py reads
  it back, between 0.98 and 1.02 of the reference volume;
- ``refused``: the run exits non-zero with an error (printed), nothing written;
- ``SHORT`` / ``OVER``: the run exits 0 but the part it deposits is off by more than 2 %.
  This is the outcome a user must never get.

The reference volume is the mesh's own enclosed volume when it is closed (every edge
shared by two faces, as trimesh judges it) and otherwise what PrusaSlicer deposits for
the same mesh at 100 % infill (its file read back by the same checker, on a bed large
enough for any of them). An open mesh's signed volume is printed beside it: where
PrusaSlicer leaves layers empty (it says so, and its warnings are printed) that is the
better guide, and the verdict takes whichever of the two the part is nearer.

Meshes in metres are run twice: as they are (a part a thousand times too small, which
Lamina should refuse) and with ``model.units = "m"`` (``--metres NAME``, repeatable; the
defaults are the ones ../shared/models/SOURCES.md names).

Usage: python3 benches/meshes.py [--models DIR] [--lamina PATH] [--pipeline NAME ...]
       [--only SUBSTRING]
Needs trimesh and numpy (the replay checker's own), and prusa-slicer for open meshes.
"""

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benches"))
import benchsuite  # noqa: E402  (the replay reading and PrusaSlicer's settings)

METRES = ["stanford_bunny.stl", "octagonal_pocket_plate.stl", "openfoam_buildings_400k.stl"]


# A bed no mesh here outgrows: only the volume PrusaSlicer deposits is wanted.
BIG_BED = ["--bed-shape", "0x0,1000x0,1000x1000,0x1000", "--max-print-height", "1000"]


def reference(mesh, scale, work, python):
    """([volume mm³, ...], how it was found) for `mesh` scaled by `scale`: the closed
    mesh's volume; or PrusaSlicer's deposit and the open mesh's signed volume."""
    import trimesh

    m = trimesh.load(mesh, force="mesh")
    signed = abs(m.volume) * scale**3
    if m.is_watertight:
        return [signed], "mesh volume"
    if not shutil.which("prusa-slicer"):
        return [signed], "open mesh's signed volume (prusa-slicer absent)"
    out = work / (Path(mesh).stem + "-prusa.gcode")
    p = subprocess.run(["prusa-slicer", *benchsuite.PRUSA_FULL, *BIG_BED, "--scale", str(scale), "--output", out, mesh],
                       capture_output=True, text=True)
    if p.returncode != 0:
        return [signed], "open mesh's signed volume; prusa-slicer failed: " + p.stderr.strip()[-120:]
    said = "; ".join(sorted({l.strip() for l in (p.stdout + p.stderr).splitlines() if "warning" in l.lower()}))
    how = "PrusaSlicer's deposit / open mesh's signed volume" + (f" (PrusaSlicer: {said})" if said else "")
    return [benchsuite.economy_of(out, python)[1], signed], how


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", default=os.environ.get("LAMINA_MODELS", str(ROOT.parent / "shared" / "models")))
    ap.add_argument("--lamina", default=str(ROOT / "target" / "release" / "lamina"))
    ap.add_argument("--python", default=sys.executable)
    ap.add_argument("--pipeline", action="append", help="pipeline name under pipelines/ (repeatable)")
    ap.add_argument("--metres", action="append", help="a mesh in metres (repeatable)")
    ap.add_argument("--only", help="only meshes whose name contains this")
    args = ap.parse_args()
    models = Path(args.models)
    pipelines = args.pipeline or ["gear-mixing-gcode", "benchy-two-tools"]
    metres = set(args.metres or METRES)
    work = Path(tempfile.mkdtemp(prefix="lamina-meshes-"))
    rows = []
    refs = {}
    for mesh in sorted(models.glob("*.stl")):
        if args.only and args.only not in mesh.name:
            continue
        runs = [("mm", 1.0)] + ([("m", 1000.0)] if mesh.name in metres else [])
        for units, scale in runs:
            key = (mesh.name, scale)
            if key not in refs:
                refs[key] = reference(mesh, scale, work, args.python)
            ref, how = refs[key]
            for pipeline in pipelines:
                out = work / f"{mesh.stem}-{units}-{pipeline}"
                cmd = [args.lamina, "run", str(ROOT / "pipelines" / f"{pipeline}.toml"), "--model", str(mesh),
                       "--allow", str(models), "--out", str(out), "--quiet"]
                if units != "mm":
                    cmd += ["--set", f'model.units="{units}"']
                t = time.monotonic()
                r = subprocess.run(cmd, capture_output=True, text=True)
                wall = time.monotonic() - t
                files = sorted(out.glob("*.gcode")) if out.exists() else []
                if r.returncode != 0:
                    first = next((l for l in r.stderr.splitlines() if l.startswith("error")), r.stderr[:160])
                    written = sorted(p.name for p in out.rglob("*") if p.is_file()) if out.exists() else []
                    verdict = "refused" if not written else "refused, LEFT FILES"
                    rows.append((mesh.name, units, pipeline, verdict, wall, None, ref, how, first.strip()[:150]))
                    continue
                if not files:
                    rows.append((mesh.name, units, pipeline, "NO G-CODE", wall, None, ref, how, ""))
                    continue
                part = benchsuite.economy_of(files[0], args.python)[1]
                ratio = min((part / r for r in ref if r), key=lambda x: abs(x - 1.0), default=None)
                if ratio is None:
                    verdict = "no reference"
                elif ratio < 0.98:
                    verdict = "SHORT"
                elif ratio > 1.02:
                    verdict = "OVER"
                else:
                    verdict = "ok"
                rows.append((mesh.name, units, pipeline, verdict, wall, part, ref, how, ""))
            print(f"... {mesh.name} ({units}) done", file=sys.stderr, flush=True)
    print(f"{'mesh':36} {'units':5} {'pipeline':18} {'verdict':10} {'wall s':>7} {'part mm3':>12} "
          f"{'ref mm3':>21} {'ratio':>15}  reference / error")
    for name, units, pipeline, verdict, wall, part, ref, how, err in rows:
        ratio = " / ".join(f"{part / r:.4f}" for r in ref if r) if part is not None else "-"
        partf = f"{part:.1f}" if part is not None else "-"
        reff = " / ".join(f"{r:.1f}" for r in ref)
        print(f"{name:36} {units:5} {pipeline:18} {verdict:10} {wall:7.1f} {partf:>12} {reff:>21} {ratio:>15}  "
              f"{err or how}")
    bad = [r for r in rows if r[3] in ("SHORT", "OVER", "NO G-CODE", "refused, LEFT FILES")]
    shutil.rmtree(work, ignore_errors=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
