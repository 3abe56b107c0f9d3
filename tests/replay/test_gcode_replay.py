"""Self-tests of the G-code replay checker (run: python3 -m unittest discover tests/replay).

Every test builds small synthetic G-code in memory; the volume and coverage
tests also build a box mesh. A well-formed file passes every check, and each
check has at least one file that breaks it.
"""

from __future__ import annotations

import io
import json
import math
import os
import sys
import tempfile
import unittest
from contextlib import redirect_stderr, redirect_stdout

import numpy as np
import shapely

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import gcode_replay as gr  # noqa: E402

FIL_AREA = math.pi * (1.75 / 2) ** 2
BED = (0.0, 0.0, 200.0, 200.0)


# ---------------------------------------------------------------------------
# Synthetic inputs
# ---------------------------------------------------------------------------

def box_arrays(sx=10.0, sy=10.0, sz=1.0, origin=(0.0, 0.0, 0.0), inward=False):
    """Vertices and outward-facing triangles of an axis-aligned box (inward
    facing when ``inward``, to cut a cavity)."""
    ox, oy, oz = origin
    v = np.array([[ox + x * sx, oy + y * sy, oz + z * sz]
                  for z in (0, 1) for y in (0, 1) for x in (0, 1)], dtype=float)
    # corners: index = x + 2y + 4z
    f = np.array([
        [0, 2, 3], [0, 3, 1],  # bottom (z=0), normal -z
        [4, 5, 7], [4, 7, 6],  # top, +z
        [0, 1, 5], [0, 5, 4],  # y=0, -y
        [2, 6, 7], [2, 7, 3],  # y=1, +y
        [0, 4, 6], [0, 6, 2],  # x=0, -x
        [1, 3, 7], [1, 7, 5],  # x=1, +x
    ], dtype=np.int64)
    if inward:
        f = f[:, ::-1].copy()
    return v, f


def write_box_stl(path, sx=10.0, sy=10.0, sz=1.0):
    import trimesh

    v, f = box_arrays(sx, sy, sz)
    trimesh.Trimesh(vertices=v, faces=f, process=False).export(path)


def box_gcode(*, layers=5, h=0.2, size=10.0, centre=(100.0, 100.0), w=0.4, e_scale=1.0,
              spacing=None, header_extra="", heat="M109 S210", zs=None, type_marker=True,
              footer_time=None, time_factor=1.0, prime=True, flavor="marlin", hop=True):
    """G-code depositing a ``size`` x ``size`` x ``layers*h`` box with X rasters.

    Each raster is its own run (retract, travel, recover), ends flush with the
    box's sides, and rasters are ``spacing`` (default: the width) apart, so the
    deposited volume and the covered area equal the box's exactly.
    """
    spacing = w if spacing is None else spacing
    cx, cy = centre
    x0, x1 = cx - size / 2, cx + size / 2
    y0 = cy - size / 2
    n = int(round(size / spacing))
    lines = [
        f"; flavor: {flavor}",
        "G21", "G90", "M82",
        "M204 P1000 T2000 R1500",
        "M140 S60", "M190 S60",
        "T0",
        heat,
        "G92 E0",
    ]
    if header_extra:
        lines.extend(header_extra.splitlines())
    e = 0.0
    if prime:
        lines += ["G0 X10 Y10 Z0.3 F6000", ";TYPE:PRIME", "G1 X60 Y10 E5.0 F1200"]
        e = 5.0
        lines += [f"G1 E{e - 1:.5f} F2100"]
        e -= 1
    else:
        lines += ["G1 E-1.00000 F2100"]
        e = -1.0
    zs = zs or [h * (k + 1) for k in range(layers)]
    for li, z in enumerate(zs):
        lines.append(f";LAYER:{li}")
        if type_marker:
            lines.append(";TYPE:PART")
        for k in range(n):
            y = y0 + spacing / 2 + k * spacing
            a, b = (x0, x1) if k % 2 == 0 else (x1, x0)
            if hop:
                lines.append(f"G0 Z{z + 0.4:.3f} F600")
            lines.append(f"G0 X{a:.4f} Y{y:.4f} F7200")
            lines.append(f"G0 Z{z:.3f} F600")
            lines.append(f"G1 E{e + 1:.5f} F2100")
            e += 1
            de = w * h * size / FIL_AREA * e_scale
            e += de
            lines.append(f"G1 X{b:.4f} Y{y:.4f} E{e:.5f} F1800")
            lines.append(f"G1 E{e - 1:.5f} F2100")
            e -= 1
    lines += ["M104 S0", "M140 S0", "M84"]
    return with_estimate("\n".join(lines) + "\n", footer_time, time_factor)


def with_estimate(text, estimate=None, factor=1.0, digits=3):
    """``text`` and its footer ``; estimated printing time: <estimate> s`` (with
    ``digits`` decimals): the checker's own replayed time x ``factor`` when
    ``estimate`` is None, and no footer when it is False."""
    if estimate is None:
        rep = gr.analyse(text, gr.Options())
        estimate = rep["time"]["replayed_s"] * factor
    if estimate is not False:
        text += f"; estimated printing time: {estimate:.{digits}f} s\n"
    return text


def run_checks(text, **kw):
    o = gr.Options(**kw)
    return gr.analyse(text, o)


def status(rep, name):
    return rep["checks"][name]["status"]


def messages(rep, name):
    return [ex["message"] for ex in rep["checks"][name]["examples"]]


# A minimal well-formed single-tool preamble for hand-written cases.
HOT = "; flavor: marlin\nG90\nM82\nM109 S210\nG92 E0\n;LAYER:0\n;TYPE:PART\nG0 X10 Y10 Z0.2 F6000\n"


# ---------------------------------------------------------------------------
# Tests
# ---------------------------------------------------------------------------

class BoxStl:
    """A test class's box mesh (``write_box_stl``'s default box) at ``cls.stl``, in a
    temporary folder removed after the class's tests."""

    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        cls.stl = os.path.join(cls.tmp.name, "box.stl")
        write_box_stl(cls.stl)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()


class WellFormed(BoxStl, unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        super().setUpClass()
        cls.text = box_gcode()
        cls.rep = run_checks(cls.text, mesh=cls.stl, bed_rect=BED, coverage_every=1)

    def test_every_check_passes(self):
        for name, c in self.rep["checks"].items():
            self.assertIn(c["status"], ("pass", "skipped"), f"{name}: {c}")
        for name in ("features", "layers", "heating", "bed", "volume", "coverage", "time"):
            self.assertEqual(status(self.rep, name), "pass", name)
        self.assertTrue(self.rep["ok"])

    def test_volume_matches_box(self):
        vol = self.rep["volume"]
        self.assertAlmostEqual(vol["mesh_mm3"], 100.0, places=6)
        self.assertAlmostEqual(vol["ratio"], 1.0, delta=1e-3)
        self.assertIn("PRIME", vol["by_type_mm3"])
        # the prime line is 5 mm of filament minus nothing (its retraction is recovered later)
        self.assertAlmostEqual(vol["by_type_mm3"]["PRIME"], 5.0 * FIL_AREA, places=3)

    def test_coverage_full_without_overlap(self):
        rows = self.rep["coverage"]["layers"]
        self.assertEqual(len(rows), 5)
        for row in rows:
            self.assertGreater(row["coverage"], 0.9999)
            self.assertLess(row["overlap"], 1e-4)  # coordinates are rounded to 0.1 um
            self.assertAlmostEqual(row["reference_mm2"], 100.0, places=6)
            self.assertLess(row["outside_mm2"], 1e-3)

    def test_layers_and_extents(self):
        self.assertEqual(self.rep["layers"]["count"], 5)
        ext = self.rep["extents"]["extrusion"]
        self.assertAlmostEqual(ext["x_min"], 10.0)  # prime line
        self.assertAlmostEqual(ext["x_max"], 105.0)
        self.assertAlmostEqual(ext["y_max"], 104.8)

    def test_filament_per_tool(self):
        fil = self.rep["tools"]["filament_mm"]
        self.assertEqual(list(fil), ["T0"])
        self.assertAlmostEqual(fil["T0"], 5.0 + 100.0 / FIL_AREA, places=3)

    def test_cli_writes_json_and_exits_0(self):
        gpath = os.path.join(self.tmp.name, "box.gcode")
        jpath = os.path.join(self.tmp.name, "box.json")
        with open(gpath, "w") as fh:
            fh.write(self.text)
        out = io.StringIO()
        with redirect_stdout(out):
            rc = gr.main([gpath, "--mesh", self.stl, "--place", "centre", "--bed", "0,0,200,200",
                          "--coverage-every", "1", "--json", jpath])
        self.assertEqual(rc, 0, out.getvalue())
        self.assertIn("RESULT: PASS", out.getvalue())
        with open(jpath) as fh:
            rep = json.load(fh)
        for key in ("file", "ok", "flavor", "checks", "layers", "volume", "coverage", "time",
                    "tools", "mix", "channels", "extents", "unknown_commands"):
            self.assertIn(key, rep)
        self.assertTrue(rep["ok"])


class Heating(unittest.TestCase):
    def test_cold_extrusion(self):
        rep = run_checks(box_gcode(heat="M109 S150", footer_time=False))
        self.assertEqual(status(rep, "heating"), "fail")
        self.assertTrue(any("cold extrusion" in m for m in messages(rep, "heating")))

    def test_heat_without_wait(self):
        rep = run_checks(box_gcode(heat="M104 S210", footer_time=False))
        self.assertEqual(status(rep, "heating"), "fail")
        self.assertTrue(any("before waiting" in m for m in messages(rep, "heating")))

    def test_retract_before_heat(self):
        text = "; flavor: marlin\nG90\nM82\nG92 E0\nG1 E-1 F2100\nM109 S210\n;TYPE:PART\nG1 E0\n"
        rep = run_checks(text)
        self.assertEqual(status(rep, "heating"), "fail")
        ex = rep["checks"]["heating"]["examples"]
        self.assertEqual(len(ex), 1)
        self.assertEqual(ex[0]["line"], 5)
        self.assertIn("retraction", ex[0]["message"])

    def test_extrusion_before_tool_selected(self):
        text = ("; flavor: marlin\nM104 T0 S210\nM109 T0 S210\n;TYPE:PART\nG0 X1 Y1 Z0.2 F600\n"
                "G1 X5 Y1 E0.2 F1200\nT0\nG1 X9 Y1 E0.4\n")
        rep = run_checks(text)
        ex = rep["checks"]["heating"]["examples"]
        self.assertEqual([e["line"] for e in ex], [6])
        self.assertIn("no tool selected", ex[0]["message"])

    def test_firmware_retract_marlin_needs_heat(self):
        rep = run_checks("; flavor: marlin\nG10\nM109 S210\nG11\n")
        self.assertEqual([e["line"] for e in rep["checks"]["heating"]["examples"]], [2])

    def test_rrf_g10_p_sets_temperatures_not_retract(self):
        text = ("; flavor: rrf\nG10 P0 S210 R150\nT0\nM116\n;LAYER:0\n;TYPE:PART\n"
                "G0 X1 Y1 Z0.2 F600\nG1 X5 Y1 E0.2 F1200\nG10\nG11\n")
        rep = run_checks(text)
        self.assertEqual(rep["flavor"], "rrf")
        self.assertEqual(status(rep, "heating"), "pass", rep["checks"]["heating"])

    def test_rrf_standby_reselect_needs_wait(self):
        base = ("; flavor: rrf\nG10 P0 S210 R150\nG10 P1 S215 R150\nT0\nM116\n;LAYER:0\n;TYPE:PART\n"
                "G0 X1 Y1 Z0.2 F600\nG1 X5 Y1 E0.2 F1200\nT1\nM116\nG1 X5 Y5 E0.4\nT0\n{wait}G1 X1 Y5 E0.6\n")
        bad = run_checks(base.format(wait=""))
        self.assertEqual(status(bad, "heating"), "fail")
        self.assertEqual([e["line"] for e in bad["checks"]["heating"]["examples"]], [14])
        self.assertIn("before waiting", bad["checks"]["heating"]["examples"][0]["message"])
        good = run_checks(base.format(wait="M116 P0\n"))
        self.assertEqual(status(good, "heating"), "pass")
        self.assertEqual(good["tools"]["changes"], 2)

    def test_marlin_standby_then_raise_needs_wait(self):
        base = (HOT + "G1 X20 Y10 E0.5 F1200\nM104 S150\nM104 S210\n{wait}G1 X30 Y10 E1.0\n")
        self.assertEqual(status(run_checks(base.format(wait="")), "heating"), "fail")
        self.assertEqual(status(run_checks(base.format(wait="M109 S210\n")), "heating"), "pass")

    def test_tool_changer_hotends_are_separate(self):
        text = ("; flavor: tool-change\nT0\nM109 T0 S210\n;LAYER:0\n;TYPE:PART\nG0 X1 Y1 Z0.2 F600\n"
                "G1 X5 Y1 E0.2 F1200\nT1\nG1 X5 Y5 E0.4\n")
        rep = run_checks(text)
        self.assertEqual([e["line"] for e in rep["checks"]["heating"]["examples"]], [9])
        self.assertIn("T1", rep["checks"]["heating"]["examples"][0]["message"])

    def test_mixing_virtual_tools_share_one_hotend(self):
        text = ("; flavor: marlin-mixing\nT0\nM109 S210\n;LAYER:0\n;TYPE:PART\nG0 X1 Y1 Z0.2 F600\n"
                "M163 S0 P0.25\nM163 S1 P0.75\nM164 S3\nT3\nG1 X5 Y1 E0.4 F1200\n")
        rep = run_checks(text)
        self.assertTrue(rep["mixing"])
        self.assertEqual(status(rep, "heating"), "pass")
        ch = rep["channels"]["filament_mm"]
        self.assertAlmostEqual(ch["0"], 0.1)
        self.assertAlmostEqual(ch["1"], 0.3)


class Bed(unittest.TestCase):
    def test_out_of_bed_travel(self):
        text = HOT + "G1 X20 Y10 E0.5 F1200\nG0 X250 Y10\nG0 X20 Y10\n"
        rep = run_checks(text, bed_rect=BED)
        self.assertEqual(status(rep, "bed"), "fail")
        self.assertEqual([e["line"] for e in rep["checks"]["bed"]["examples"]], [10])

    def test_round_bed(self):
        text = HOT.replace("X10 Y10", "X0 Y0") + "G1 X50 Y0 E0.5 F1200\nG0 X80 Y80\n"
        rep = run_checks(text, bed_circle=(0.0, 0.0, 100.0))
        self.assertEqual([e["line"] for e in rep["checks"]["bed"]["examples"]], [10])

    def test_g92_shift_is_machine_space(self):
        # G92 X0 at machine X190: a move to logical X15 reaches machine X205.
        text = HOT + "G0 X190 Y10\nG92 X0\nG0 X5\nG0 X15\n"
        rep = run_checks(text, bed_rect=BED)
        self.assertEqual([e["line"] for e in rep["checks"]["bed"]["examples"]], [12])


class Layers(unittest.TestCase):
    def test_decreasing_layer_z(self):
        rep = run_checks(box_gcode(layers=3, zs=[0.2, 0.4, 0.3], footer_time=False))
        self.assertEqual(status(rep, "layers"), "fail")
        self.assertTrue(any("below the previous layer" in m for m in messages(rep, "layers")))

    def test_z_hop_inside_layer_is_fine(self):
        rep = run_checks(box_gcode(layers=2, hop=True, footer_time=False))
        self.assertEqual(status(rep, "layers"), "pass")

    def test_extrusion_off_the_layer_z(self):
        text = HOT + "G1 X20 Y10 E0.5 F1200\nG0 Z0.6\nG1 X30 Y10 E1.0\n"
        rep = run_checks(text)
        self.assertEqual([e["line"] for e in rep["checks"]["layers"]["examples"]], [11])


class Features(unittest.TestCase):
    def test_extrusion_without_type_marker(self):
        rep = run_checks(box_gcode(layers=1, type_marker=False, prime=False, footer_time=False))
        self.assertEqual(status(rep, "features"), "fail")
        self.assertEqual(rep["checks"]["features"]["violations"], 25)
        self.assertIn("(none)", rep["volume"]["by_type_mm3"])

    def test_volume_per_type(self):
        text = (HOT.replace(";TYPE:PART\n", ";TYPE:SKIRT\n") + "G1 X20 Y10 E1.0 F1200\n;TYPE:TOWER\n"
                "G1 X20 Y20 E3.0\n;TYPE:PART\nG1 X10 Y20 E3.5\n")
        rep = run_checks(text)
        by = rep["volume"]["by_type_mm3"]
        self.assertAlmostEqual(by["SKIRT"], 1.0 * FIL_AREA, places=5)
        self.assertAlmostEqual(by["TOWER"], 2.0 * FIL_AREA, places=5)
        self.assertAlmostEqual(by["PART"], 0.5 * FIL_AREA, places=5)


class Mixes(unittest.TestCase):
    def mix(self, body):
        return run_checks("; flavor: marlin-mixing\nT0\nM109 S210\n" + body)

    def test_bad_m163_sum(self):
        rep = self.mix("M163 S0 P0.6\nM163 S1 P0.6\nM164 S0\n")
        self.assertEqual(status(rep, "mixes"), "fail")
        self.assertEqual(rep["checks"]["mixes"]["examples"][0]["line"], 6)

    def test_two_decimal_rounding_is_accepted(self):
        rep = self.mix("M163 S0 P0.33\nM163 S1 P0.33\nM163 S2 P0.33\nM164 S0\nM165 A0.5 B0.5\n")
        self.assertEqual(status(rep, "mixes"), "pass")
        self.assertEqual(rep["mix"]["commands"], 2)
        self.assertEqual(rep["mix"]["changes"], 2)

    def test_unchanged_mix_is_not_a_change(self):
        rep = self.mix("M163 S0 P0.5\nM163 S1 P0.5\nM164 S0\nM164 S0\n")
        self.assertEqual(rep["mix"]["commands"], 2)
        self.assertEqual(rep["mix"]["changes"], 1)

    def test_bad_m165_and_m567(self):
        self.assertEqual(status(self.mix("M165 A0.5 B0.3\n"), "mixes"), "fail")
        rep = run_checks("; flavor: rrf\nM563 P0 D0:1 H1\nM567 P0 E0.7:0.2\n")
        self.assertEqual(status(rep, "mixes"), "fail")
        rep = run_checks("; flavor: rrf\nM563 P0 D0:1 H1\nM567 P0 E0.7:0.3\n")
        self.assertEqual(status(rep, "mixes"), "pass")


class Volume(BoxStl, unittest.TestCase):
    def test_under_fill_fails_volume_and_coverage(self):
        rep = run_checks(box_gcode(e_scale=0.8, footer_time=False), mesh=self.stl, bed_rect=BED)
        self.assertEqual(status(rep, "volume"), "fail")
        self.assertAlmostEqual(rep["volume"]["ratio"], 0.8, delta=2e-3)
        self.assertEqual(status(rep, "coverage"), "fail")
        self.assertAlmostEqual(rep["coverage"]["worst_coverage"]["coverage"], 0.8, delta=2e-3)

    def test_overlapping_rasters_fail_overlap(self):
        # rasters 0.3 apart at width 0.4: a quarter of each bead overlaps the next
        rep = run_checks(box_gcode(spacing=0.3, footer_time=False, layers=1), mesh=self.stl, bed_rect=BED)
        self.assertEqual(status(rep, "coverage"), "fail")
        self.assertGreater(rep["coverage"]["worst_overlap"]["overlap"], 0.2)

    def test_misplaced_part_loses_coverage(self):
        rep = run_checks(box_gcode(footer_time=False, layers=1), mesh=self.stl, bed_rect=BED, place="103,100")
        self.assertAlmostEqual(rep["coverage"]["layers"][0]["coverage"], 0.7, delta=1e-3)

    def test_retractions_cancel_and_relative_e_agrees(self):
        absolute = HOT + "G1 X20 Y10 E1.0 F1200\nG1 E0.0 F2100\nG0 X20 Y20\nG1 E1.0\nG1 X10 Y20 E2.0 F1200\n"
        relative = HOT.replace("M82", "M83") + ("G1 X20 Y10 E1.0 F1200\nG1 E-1.0 F2100\nG0 X20 Y20\n"
                                               "G1 E1.0\nG1 X10 Y20 E1.0 F1200\n")
        for text in (absolute, relative):
            rep = run_checks(text)
            self.assertAlmostEqual(rep["volume"]["part_mm3"], 2.0 * FIL_AREA, places=6)

    def test_g92_e_reset(self):
        text = HOT + "G1 X20 Y10 E1.0 F1200\nG92 E0\nG1 X30 Y10 E1.0\n"
        self.assertAlmostEqual(run_checks(text)["volume"]["part_mm3"], 2.0 * FIL_AREA, places=6)

    def test_recovery_beyond_retraction_counts(self):
        # retract 1, recover 1.5: the extra 0.5 mm is pushed (a blob)
        text = HOT + "G1 X20 Y10 E1.0 F1200\nG1 E0.0 F2100\nG1 E1.5\n"
        self.assertAlmostEqual(run_checks(text)["volume"]["part_mm3"], 1.5 * FIL_AREA, places=6)


class Mesh(unittest.TestCase):
    def test_signed_volume_of_a_box(self):
        v, f = box_arrays(3.0, 4.0, 5.0, origin=(7.0, -2.0, 1.0))
        self.assertAlmostEqual(gr.mesh_volume(v, f), 60.0, places=9)

    def test_section_with_a_cavity_is_even_odd(self):
        v1, f1 = box_arrays(10, 10, 2)
        v2, f2 = box_arrays(4, 4, 2, origin=(3, 3, 0), inward=True)
        v = np.vstack([v1, v2])
        f = np.vstack([f1, f2 + len(v1)])
        self.assertAlmostEqual(gr.mesh_volume(v, f), 200.0 - 32.0, places=9)
        sec = gr.MeshSlicer(v, f).section(1.0)
        self.assertAlmostEqual(sec.area, 100.0 - 16.0, places=9)
        self.assertEqual(len(sec.interiors) if sec.geom_type == "Polygon" else -1, 1)

    def test_section_outside_the_mesh_is_empty(self):
        v, f = box_arrays()
        self.assertEqual(gr.MeshSlicer(v, f).section(5.0).area, 0.0)

    def test_consecutive_segments_do_not_count_as_overlap(self):
        # one continuous zig-zag with sharp corners: only consecutive segments overlap
        segs = [(0, 0, 5, 0, 0, 1), (5, 0, 5, 5, 0, 1), (5, 5, 0, 5.5, 0, 1)]
        segs = [(a, b, c, d, 0.4 * 0.2 * math.hypot(c - a, d - b) / FIL_AREA, r) for a, b, c, d, _, r in segs]
        union, bead, consecutive, width = gr.bead_geometry(segs, 0.2, FIL_AREA)
        np.testing.assert_allclose(width, 0.4)
        self.assertGreater(consecutive, 0.0)
        self.assertLess(abs(bead - union.area - consecutive), 1e-9)


    def test_round_bead_ends_fill_outer_corners(self):
        # an L-shaped run: flat ends leave the outer corner square empty
        segs = [(0, 0, 5, 0, 0, 1), (5, 0, 5, 5, 0, 1)]
        segs = [(a, b, c, d, 0.4 * 0.2 * math.hypot(c - a, d - b) / FIL_AREA, r) for a, b, c, d, _, r in segs]
        flat, _, _, _ = gr.bead_geometry(segs, 0.2, FIL_AREA)
        rnd, bead, cons, _ = gr.bead_geometry(segs, 0.2, FIL_AREA, ends="round")
        corner = shapely.box(5.0, -0.2, 5.2, 0.0)
        self.assertAlmostEqual(flat.intersection(corner).area, 0.0)
        self.assertGreater(rnd.intersection(corner).area, 0.02)
        self.assertLess(abs(bead - rnd.area - cons), 1e-9)


class Time(unittest.TestCase):
    def test_trapezoid_and_triangle(self):
        self.assertAlmostEqual(gr.trapezoid_time(100.0, 0, 0, 50.0, 1000.0), 100 / 50 + 50 / 1000)
        self.assertAlmostEqual(gr.trapezoid_time(1.0, 0, 0, 100.0, 1000.0), 2 * math.sqrt(1 / 1000))
        self.assertAlmostEqual(gr.trapezoid_time(10.0, 50.0, 50.0, 50.0, 1000.0), 0.2)

    def test_single_move_from_rest_to_rest(self):
        m = gr.make_move(100.0, 0, 0, 0, 50.0, 1000.0, stop_before=True)
        self.assertAlmostEqual(gr.replay_time([m], 0.013, None), 2.05)

    def test_collinear_moves_do_not_slow_down(self):
        one = [gr.make_move(100.0, 0, 0, 0, 50.0, 1000.0, True)]
        split = [gr.make_move(25.0, 0, 0, 0, 50.0, 1000.0, i == 0) for i in range(4)]
        self.assertAlmostEqual(gr.replay_time(split, 0.013, None), gr.replay_time(one, 0.013, None))

    def test_right_angle_junction_deviation(self):
        a, jd, v, L = 1000.0, 0.013, 50.0, 20.0
        moves = [gr.make_move(L, 0, 0, 0, v, a, True), gr.make_move(0, L, 0, 0, v, a)]
        s = math.sin(math.pi / 4)
        vj = math.sqrt(a * jd * s / (1 - s))
        expect = gr.trapezoid_time(L, 0, vj, v, a) * 2
        self.assertAlmostEqual(gr.replay_time(moves, jd, None), expect)
        # a reversal stops dead
        back = [gr.make_move(L, 0, 0, 0, v, a, True), gr.make_move(-L, 0, 0, 0, v, a)]
        self.assertAlmostEqual(gr.replay_time(back, jd, None), 2 * gr.trapezoid_time(L, 0, 0, v, a))

    def test_jerk_junction(self):
        a, v, L = 1000.0, 50.0, 20.0
        jerk = [10.0, 10.0, 0.3, 5.0]
        moves = [gr.make_move(L, 0, 0, 0, v, a, True), gr.make_move(0, L, 0, 0, v, a)]
        # start/end at the safe speed 10, junction where |v*(0-1)| <= 10 -> 10
        expect = 2 * gr.trapezoid_time(L, 10.0, 10.0, v, a)
        self.assertAlmostEqual(gr.replay_time(moves, 0.013, jerk), expect)

    def test_breakdown_by_kind(self):
        moves = [gr.make_move(10.0, 0, 0, 0, 50.0, 1000.0, True), gr.make_move(10.0, 0, 0, 0.5, 50.0, 1000.0, True),
                 gr.make_move(0, 0, 0, -1.0, 35.0, 1000.0, True)]
        kinds = {}
        total = gr.replay_time(moves, 0.013, None, kinds)
        self.assertAlmostEqual(kinds["travel"], gr.trapezoid_time(10.0, 0, 0, 50.0, 1000.0))
        self.assertAlmostEqual(kinds["print"], kinds["travel"])
        self.assertAlmostEqual(kinds["e_only"], gr.trapezoid_time(1.0, 0, 0, 35.0, 1000.0))
        self.assertAlmostEqual(sum(kinds.values()), total)

    def test_file_accelerations_feeds_and_dwell(self):
        text = "; flavor: marlin\nG90\nM204 T500\nG0 X0 Y0 F6000\nG0 X100 F6000\nG4 P1500\nG4 S2\n"
        rep = run_checks(text)
        # first move has unknown start: nothing moves; second is 100 mm at 100 mm/s, a=500
        self.assertAlmostEqual(rep["time"]["replayed_s"], 1.0 + 100 / 500 + 3.5, places=9)

    def test_rrf_max_speed_is_mm_per_min(self):
        text = "; flavor: rrf\nG90\nM203 X6000 Y6000\nM204 T1000\nG0 X0 Y0 F12000\nG0 X100 F12000\n"
        rep = run_checks(text)
        self.assertAlmostEqual(rep["time"]["replayed_s"], 100 / 100 + 100 / 1000, places=9)
        marlin = run_checks(text.replace("rrf", "marlin").replace("X6000 Y6000", "X100 Y100"))
        self.assertAlmostEqual(marlin["time"]["replayed_s"], rep["time"]["replayed_s"], places=9)

    def test_wrong_time_estimate_fails(self):
        rep = run_checks(box_gcode(time_factor=2.0))
        self.assertEqual(status(rep, "time"), "fail")
        self.assertAlmostEqual(rep["time"]["rel_error"], 1.0, places=3)
        rep = run_checks(box_gcode(time_factor=1.03))
        self.assertEqual(status(rep, "time"), "pass")

    def test_missing_estimate_is_skipped(self):
        rep = run_checks(box_gcode(footer_time=False))
        self.assertEqual(status(rep, "time"), "skipped")


MARLIN = "; flavor: marlin\n"
RRF = "; flavor: rrf\n"
# 100 mm at 100 mm/s from rest to rest with the stock 3000 mm/s^2.
MOVE_S = 2 * 100 / 3000 + (100 - 100 ** 2 / 3000) / 100


def timed(text, **kw):
    """The time section of ``text``'s report, with ``kw`` as options."""
    return run_checks(text, **kw)["time"]


class HeatingWaits(unittest.TestCase):
    """The heating model (``--heating-rate``) and tool changes in the time replay."""

    def test_marlin_m109_heats_from_ambient_then_holds_the_residency(self):
        t = timed(MARLIN + "M104 S215\nM109 S215\n", heating_rate=2.0)
        # to TEMP_WINDOW below the target at 2 degC/s from 25 degC, then TEMP_RESIDENCY_TIME
        self.assertAlmostEqual(t["heating_wait_s"], (215 - 1 - 25) / 2 + 10)
        self.assertAlmostEqual(t["replayed_s"], 104.5)
        self.assertEqual(t["heating_waits"], [{"line": 3, "wait_s": 104.5}])
        self.assertEqual(t["heating_model"]["residency_s"], 10.0)

    def test_heating_before_the_wait_shortens_it(self):
        # 50 s of dwell heat the hotend to 125 degC: the wait is what is left.
        t = timed(MARLIN + "M104 S215\nG4 S50\nM109 S215\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], (214 - 125) / 2 + 10)
        self.assertAlmostEqual(t["replayed_s"], 104.5)

    def test_preheated_hotend(self):
        text = MARLIN + "M104 S215\nG4 S200\nM109 S215\n"
        # At the target: without residency the wait ends at once.
        t = timed(text, heating_rate=2.0, residency=0.0)
        self.assertEqual(t["heating_wait_s"], 0.0)
        self.assertAlmostEqual(t["replayed_s"], 200.0)
        # Marlin with residency, already inside TEMP_WINDOW on its first pass: the
        # timer starts R/3 in the future, and current Marlin's unsigned PENDING
        # ends the wait at once.
        t = timed(text, heating_rate=2.0)
        self.assertEqual(t["heating_wait_s"], 0.0)
        # RepRapFirmware: within the tolerance, no wait.
        t = timed(RRF + "G10 P0 S215 R150\nT0\nG4 S200\nM116 P0\n", heating_rate=2.0)
        self.assertEqual(t["heating_wait_s"], 0.0)

    def test_m109_s_does_not_wait_for_cooling_but_r_does(self):
        t = timed(MARLIN + "M109 S215\nM109 S200\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], 104.5)
        t = timed(MARLIN + "M109 S215\nM109 R200\n", heating_rate=2.0, cooling_rate=1.0)
        # cools from 215 to TEMP_WINDOW above 200 at 1 degC/s, then the residency
        self.assertAlmostEqual(t["heating_wait_s"], 104.5 + (215 - 201) / 1 + 10)

    def test_target_change_is_stamped_with_the_moves_before_it(self):
        move = "G92 X0 Y0 Z0\nG1 X100 F6000\n"
        self.assertAlmostEqual(timed(MARLIN + move, heating_rate=2.0)["replayed_s"], MOVE_S)
        # Set before the move, the hotend heats during it: the total is the wait alone.
        t = timed(MARLIN + "G92 X0 Y0 Z0\nM104 S215\nG1 X100 F6000\nM109 S215\n", heating_rate=2.0)
        self.assertAlmostEqual(t["replayed_s"], 104.5)
        self.assertAlmostEqual(t["heating_wait_s"], 104.5 - MOVE_S)
        # Set after it, nothing heats during the move.
        t = timed(MARLIN + move + "M104 S215\nM109 S215\n", heating_rate=2.0)
        self.assertAlmostEqual(t["replayed_s"], MOVE_S + 104.5)

    def test_marlin_bed(self):
        t = timed(MARLIN + "M140 S60\nM190 S60\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], (60 - 1 - 25) / 0.5 + 10)
        t = timed(MARLIN + "M190 S60\n", heating_rate=2.0, bed_heating_rate=1.0, bed_residency=0.0)
        self.assertAlmostEqual(t["heating_wait_s"], 60 - 25)
        # M190 with neither S nor R sets nothing and does not wait.
        self.assertEqual(timed(MARLIN + "M140 S60\nM190\n", heating_rate=2.0)["heating_wait_s"], 0.0)

    def test_rrf_m116_tools_standby_and_tolerance(self):
        setup = RRF + "G10 P0 S215 R150\nG10 P1 S220 R150\nT0\n"
        t = timed(setup + "M116 P0\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], (215 - 2 - 25) / 2)  # 2 degC tolerance, no residency
        t = timed(setup + "M116 P0 S5\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], (215 - 5 - 25) / 2)
        t = timed(setup + "M116 P0\nT1\nM116 P1\nT0\nM116 P0\n", heating_rate=2.0)
        # T1 heats from ambient; meanwhile T0 cools to its standby 150 degC and stays there.
        w1 = (220 - 2 - 25) / 2
        self.assertGreater(w1, (215 - 150) / 1.0)
        self.assertEqual([w["line"] for w in t["heating_waits"]], [5, 7, 9])
        self.assertAlmostEqual(t["heating_waits"][1]["wait_s"], w1)
        self.assertAlmostEqual(t["heating_waits"][2]["wait_s"], (215 - 2 - 150) / 2)
        # M116 alone waits for every heater, the bed included.
        t = timed(RRF + "M140 S90\nG10 P0 S215 R150\nT0\nM116\n", heating_rate=2.0)
        self.assertAlmostEqual(t["heating_wait_s"], (90 - 2 - 25) / 0.5)

    def test_tool_changes(self):
        t = timed(MARLIN + "T0\nT1\nT0\n", tool_change_time=5.0)
        self.assertEqual(t["tool_change_s"], 10.0)
        self.assertAlmostEqual(t["replayed_s"], 10.0)
        self.assertEqual(t["dwell_s"], 0.0)
        # Not T-1, not the same tool again, not the first selection after none.
        t = timed(RRF + "T0\nT0\nT1\nT-1\nT1\n", tool_change_time=5.0)
        self.assertEqual(t["tool_change_s"], 5.0)
        # A mixing head's tools are mixes of one nozzle.
        mix = MARLIN + "M163 S0 P0.5\nM163 S1 P0.5\nM164 S1\nT0\nT1\nT0\n"
        self.assertEqual(timed(mix, tool_change_time=5.0)["tool_change_s"], 0.0)

    def test_tool_change_comes_before_rrf_heats_the_new_tool(self):
        text = RRF + "G10 P0 S215 R150\nG10 P1 S215 R150\nT0\nM116\nT1\nM116 P1\n"
        t = timed(text, heating_rate=2.0, tool_change_time=5.0)
        self.assertAlmostEqual(t["heating_wait_s"], 2 * (215 - 2 - 25) / 2)
        self.assertAlmostEqual(t["replayed_s"], 2 * 94 + 5)

    def test_off_without_a_heating_rate(self):
        text = box_gcode(footer_time=False)
        off = timed(text)
        self.assertEqual(off["heating_wait_s"], 0.0)
        self.assertEqual(off["tool_change_s"], 0.0)
        self.assertIsNone(off["heating_model"])
        self.assertEqual(timed(MARLIN + "M104 S215\nM109 S215\nM190 S60\n")["replayed_s"], 0.0)
        on = timed(text, heating_rate=2.0)
        # M190 S60 from ambient, then M109 S210: the hotend had no target before it.
        self.assertAlmostEqual(on["heating_wait_s"], ((60 - 1 - 25) / 0.5 + 10) + ((210 - 1 - 25) / 2 + 10))
        self.assertAlmostEqual(on["replayed_s"] - on["heating_wait_s"], off["replayed_s"])

    def test_multi_motion_times_tool_changes_and_waits(self):
        # The prologue's M116 P0 (94 s) starts the fork; stream 1 then heats T1
        # from ambient (94 s) and changes to T2 (5 s). Details: test_multi_motion.
        text = (RRF + "G10 P0 S215 R150\nG10 P1 S215 R150\nT0\nM116 P0\nM606 S1\nM596 P1\nM83\n"
                "T1\nM116 P1\nT2\nM598\n")
        rep = run_checks(text, heating_rate=2.0, tool_change_time=5.0)
        self.assertEqual(rep["mode"], "multi-motion")
        self.assertAlmostEqual(rep["time"]["heating_wait_s"], 2 * (215 - 2 - 25) / 2)
        self.assertEqual(rep["time"]["tool_change_s"], 5.0)
        self.assertAlmostEqual(rep["time"]["replayed_s"], 94 + 94 + 5)
        self.assertEqual([(w["system"], w["line"]) for w in rep["time"]["heating_waits"]], [(0, 5), (1, 10)])
        self.assertFalse(any("not modelled" in w for w in rep["warnings"]))

    def test_cli_options(self):
        _, o, _ = gr.parse_args(["f.gcode", "--heating-rate", "2", "--cooling-rate", "0.8",
                                 "--bed-heating-rate", "0.4", "--residency", "5", "--bed-residency", "7",
                                 "--ambient", "20", "--tool-change-time", "3"])
        self.assertEqual((o.heating_rate, o.cooling_rate, o.bed_heating_rate, o.residency, o.bed_residency,
                          o.ambient, o.tool_change_time), (2.0, 0.8, 0.4, 5.0, 7.0, 20.0, 3.0))
        _, o, _ = gr.parse_args(["f.gcode"])
        self.assertIsNone(o.heating_rate)
        self.assertEqual(o.tool_change_time, 0.0)
        with redirect_stderr(io.StringIO()) as err:
            self.assertEqual(gr.main(["f.gcode", "--residency", "5"]), 2)  # the model is off
            self.assertEqual(gr.main(["f.gcode", "--heating-rate", "0"]), 2)
            self.assertEqual(gr.main(["f.gcode", "--tool-change-time", "-1"]), 2)
        self.assertIn("--heating-rate", err.getvalue())
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "heat.gcode")
            with open(path, "w") as fh:
                fh.write(MARLIN + "M104 S215\nM109 S215\nT0\nT1\n; estimated printing time: 108.5 s\n")
            out = io.StringIO()
            with redirect_stdout(out):
                rc = gr.main([path, "--heating-rate", "2", "--tool-change-time", "4",
                              "--json", os.path.join(tmp, "r.json")])
            self.assertEqual(rc, 0, out.getvalue())
            self.assertIn("heating waits 104, tool changes 4)", out.getvalue())
            with open(os.path.join(tmp, "r.json")) as fh:
                rep = json.load(fh)
            self.assertEqual(rep["time"]["heating_wait_s"], 104.5)
            self.assertEqual(rep["time"]["tool_change_s"], 4.0)


class Parsing(unittest.TestCase):
    def test_glued_words_comments_and_checksums(self):
        text = HOT + "G1X20Y10E0.5F1200 ; a comment\nN12 G1 X30 Y10 E1.0*57\n"
        rep = run_checks(text)
        self.assertAlmostEqual(rep["volume"]["part_mm3"], 1.0 * FIL_AREA, places=6)

    def test_arc_volume_counts_with_a_warning(self):
        rep = run_checks(HOT + "G2 X20 Y10 I5 J0 E0.5 F1200\n")
        self.assertAlmostEqual(rep["volume"]["part_mm3"], 0.5 * FIL_AREA, places=6)
        self.assertTrue(any("arcs" in w for w in rep["warnings"]))

    def test_unknown_commands_are_listed_not_failed(self):
        rep = run_checks(HOT + "M117 Hello\nM84\nM84\n")
        self.assertEqual(rep["unknown_commands"], {"M117": 1, "M84": 2})
        self.assertEqual(status(rep, "parse"), "pass")

    def test_bad_word_names_the_line(self):
        with self.assertRaises(gr.ParseError) as ctx:
            run_checks(HOT + "G1 Xabc Y2\n")
        self.assertEqual(ctx.exception.line, 9)

    def test_cli_parse_error_exits_2(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "bad.gcode")
            with open(path, "w") as fh:
                fh.write("G1 X1\nG1 Y2 Z#\n")
            err = io.StringIO()
            with redirect_stderr(err), redirect_stdout(io.StringIO()):
                rc = gr.main([path])
            self.assertEqual(rc, 2)
            self.assertIn(":2:", err.getvalue())

    def test_cli_failure_exits_1(self):
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "cold.gcode")
            with open(path, "w") as fh:
                fh.write(box_gcode(heat="M109 S150", footer_time=False))
            with redirect_stdout(io.StringIO()):
                rc = gr.main([path, "--json", os.path.join(tmp, "r.json")])
            self.assertEqual(rc, 1)

    def test_cli_negative_coordinates(self):
        path, opts, _ = gr.parse_args(["f.gcode", "--bed", "-100,-100,100,100", "--place", "-5,2"])
        self.assertEqual(opts.bed_rect, (-100.0, -100.0, 100.0, 100.0))
        self.assertEqual(opts.place, "-5,2")
        self.assertEqual(gr.placement_target(opts), (-5.0, 2.0))

    def test_cli_usage_error_exits_2(self):
        with redirect_stderr(io.StringIO()):
            self.assertEqual(gr.main(["x.gcode", "--bed", "1,2,3"]), 2)
            self.assertEqual(gr.main([]), 2)

    def test_flavor_from_header(self):
        self.assertEqual(run_checks("; flavor: rrf\n")["flavor"], "rrf")
        self.assertEqual(run_checks("; flavor: marlin-mixing, 3 layers\n")["flavor"], "marlin")
        self.assertEqual(run_checks("G90\n")["flavor"], "marlin")
        self.assertEqual(run_checks("; flavor: rrf\n", flavor="marlin")["flavor"], "marlin")


if __name__ == "__main__":
    unittest.main()
