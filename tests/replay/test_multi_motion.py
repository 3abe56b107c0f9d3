"""Self-tests of the multiple-motion-system replay (run: python3 -m unittest discover tests/replay).

Small synthetic two-stream RepRapFirmware jobs: system 0 drives X/Y, system 1
drives U/V (two independent gantries), both share Z. A clean concurrent file
passes; crossings, cold tools, wrong estimates and firmware-rule breaches are
each caught.
"""

from __future__ import annotations

import io
import json
import math
import os
import sys
import tempfile
import unittest
from contextlib import redirect_stdout

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

import gcode_replay as gr  # noqa: E402
import multi_motion as mmod  # noqa: E402
import test_gcode_replay as tg  # noqa: E402

FIL_AREA = math.pi * (1.75 / 2) ** 2

HEADER = """; flavor: rrf
; motion system 0: X axis X, Y axis Y, Z axis Z, envelope {r0} mm, home X 0 Y 0
; motion system 1: X axis U, Y axis V, Z axis Z, envelope {r1} mm, home X 300 Y 300
G21
G90
M83
M204 P1000 T2000
G10 P0 S{t0} R150
G10 P1 S{t1} R150
G1 Z0.2 F600
M606 S1
M596 P0
T0
M116 P0
M596 P1
M83
M204 P1000 T2000
T1
M116 P1
M598
"""

#: The end of a job: each system turns its own tool's heater off.
END = "M596 P1\nM568 P1 S0 R0 A0\nM596 P0\nM568 P0 S0 R0 A0\n"


def job(body: str, *, r0=5.0, r1=5.0, t0=210, t1=210, estimate=None, factor=1.0, extra_footer="",
        header=None) -> str:
    """A two-stream job: header (tools heated, forked), ``body``, a final
    M598, and the estimated printing time (replayed x ``factor`` unless given;
    ``False`` for none)."""
    text = (header if header is not None else HEADER.format(r0=r0, r1=r1, t0=t0, t1=t1)) + body
    if not text.endswith("\n"):
        text += "\n"
    text += "M598\n" + END + extra_footer
    return tg.with_estimate(text, estimate, factor, digits=4)


def clean_layers(layers=3, h=0.2) -> tuple[str, dict]:
    """Both heads print a 40 mm square outline per layer, head 0 near X 20..60,
    head 1 near U 220..260, with M598 around each layer change (stream 0
    moves the shared Z). Returns the body and the filament per tool (mm)."""
    body = []
    e_per_mm = 0.05
    fil = {"T0": 0.0, "T1": 0.0}
    for li in range(layers):
        z = h * (li + 1)
        body.append("M596 P0")
        body.append(f"G1 Z{z:.3f} F600")
        body.append("M598")
        for sysno, (x0, letterx, lettery) in enumerate(((20.0, "X", "Y"), (220.0, "U", "V"))):
            body.append(f"M596 P{sysno}")
            body.append(f";LAYER:{li}")
            body.append(";TYPE:PART")
            body.append(f"G0 {letterx}{x0:.3f} {lettery}20 F6000")
            if li > 0:
                body.append("G1 E1 F2400")
            pts = [(x0 + 40, 20), (x0 + 40, 60), (x0, 60), (x0, 20)]
            for (px, py) in pts:
                e = 40 * e_per_mm
                body.append(f"G1 {letterx}{px:.3f} {lettery}{py:.3f} E{e:.5f} F1800")
                fil[f"T{sysno}"] += e
            # Pulled back before the barrier, pushed out again at the next outline.
            body.append("G1 E-1 F2400")
        body.append("M598")
    return "\n".join(body) + "\n", fil


def crossing_body(offset: float, barrier: bool) -> str:
    """Head 0 runs along Y 100 from X 50 to X 150 and then leaves the lane to
    Y 50; head 1 runs the other way along V = 100 + offset from U 200 to U 50.
    Without a barrier they pass each other ``offset`` apart; with one, head 1
    starts after head 0 has left."""
    return "\n".join([
        "M596 P0", "G0 X50 Y100 F12000",
        "M596 P1", f"G0 U200 V{100 + offset:.7f} F12000",
        "M598",
        "M596 P0", "G0 X150 Y100", "G0 X150 Y50",
        *(["M598"] if barrier else []),
        "M596 P1", "G0 U50",
    ]) + "\n"


def run(text, **kw):
    return gr.analyse(text, gr.Options(**kw))


def status(rep, name):
    return rep["checks"][name]["status"]


def messages(rep, name):
    return [ex["message"] for ex in rep["checks"][name]["examples"]]


class CleanConcurrent(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        body, cls.fil = clean_layers()
        cls.text = job(body, extra_footer="; sequential build time: 100 s\n")
        cls.rep = run(cls.text, bed_rect=(0.0, 0.0, 300.0, 300.0))

    def test_detected_and_every_check_passes(self):
        rep = self.rep
        self.assertEqual(rep["mode"], "multi-motion")
        for name, c in rep["checks"].items():
            self.assertIn(c["status"], ("pass", "skipped"), f"{name}: {c}")
        for name in ("streams", "features", "layers", "heating", "bed", "time", "collisions"):
            self.assertEqual(status(rep, name), "pass", name)
        self.assertTrue(rep["ok"])
        self.assertEqual(rep["collisions"]["count"], 0)
        self.assertGreater(rep["collisions"]["closest_mm"], 100.0)

    def test_streams_run_concurrently(self):
        t = self.rep["time"]
        rows = self.rep["streams"]
        # both heads print the same amount at the same speeds: the build takes
        # about what one stream takes, far less than the two one after the other
        self.assertLess(t["replayed_s"], 0.7 * t["streams_sum_s"])
        for row in rows:
            self.assertAlmostEqual(row["busy_s"] + row["wait_s"], t["replayed_s"], places=9)
            self.assertAlmostEqual(row["paused_share"], row["wait_s"] / t["replayed_s"], places=12)
        self.assertEqual(t["barriers"], 2 + 2 * 3 + 1 + 1)  # fork, header M598, layers, final M598, end
        self.assertAlmostEqual(t["ratio_to_sequential"], t["replayed_s"] / 100.0)
        self.assertEqual(t["tolerance"], 0.02)

    def test_extrusion_per_tool_and_stream(self):
        ex = self.rep["extrusion"]
        self.assertEqual(list(ex["by_stream"]["0"]["filament_mm"]), ["T0"])
        self.assertEqual(list(ex["by_stream"]["1"]["filament_mm"]), ["T1"])
        for tool in ("T0", "T1"):
            self.assertAlmostEqual(ex["filament_mm"][tool], self.fil[tool], places=9)
            self.assertAlmostEqual(ex["volume_mm3"][tool], self.fil[tool] * FIL_AREA, places=9)
            self.assertAlmostEqual(ex["part_mm3"][tool], self.fil[tool] * FIL_AREA, places=9)
        self.assertEqual(self.rep["tools"]["filament_mm"], ex["filament_mm"])

    def test_layers_per_stream_follow_the_shared_z(self):
        for row in self.rep["streams"]:
            self.assertEqual(row["layers"]["count"], 3)
            self.assertAlmostEqual(row["layers"]["z_first"], 0.2)
            self.assertAlmostEqual(row["layers"]["z_last"], 0.6)

    def test_timing_matches_single_stream_replay(self):
        # stream 1 alone, as a one-system file, times the same per layer
        body, _ = clean_layers(layers=1)
        rep = run(job(body, estimate=False))
        single = "\n".join(["; flavor: rrf", "G21", "G90", "M83", "M204 P1000 T2000", "G10 P0 S210 R150",
                            "T0", "M116", "G0 X300 Y300 Z0.2", "G4 P0", ";LAYER:0", ";TYPE:PART",
                            "G0 X220 Y20 F6000"]
                           + [f"G1 X{x} Y{y} E2.00000 F1800" for x, y in ((260, 20), (260, 60), (220, 60), (220, 20))]
                           + ["G1 E-1 F2400"])
        ref = run(single + "\n")
        self.assertAlmostEqual(rep["streams"][1]["busy_s"], ref["time"]["replayed_s"], places=9)


class Collisions(unittest.TestCase):
    def test_heads_crossing_without_barrier_collide(self):
        rep = run(job(crossing_body(3.0, barrier=False)))
        self.assertEqual(status(rep, "collisions"), "fail")
        c = rep["collisions"]
        self.assertEqual(c["count"], 1)
        ex = c["examples"][0]
        self.assertAlmostEqual(ex["distance_mm"], 3.0, places=6)
        self.assertEqual(ex["required_mm"], 10.0)
        p0, p1 = ex["positions"]["0"], ex["positions"]["1"]
        self.assertAlmostEqual(p0[0], p1[0], places=6)  # they pass each other: same X
        self.assertAlmostEqual(p0[1], 100.0)
        self.assertFalse(rep["ok"])

    def test_barrier_resolves_the_crossing(self):
        rep = run(job(crossing_body(3.0, barrier=True)))
        self.assertEqual(status(rep, "collisions"), "pass", rep["checks"]["collisions"])
        self.assertEqual(rep["collisions"]["count"], 0)
        self.assertTrue(rep["ok"], [(k, c["examples"]) for k, c in rep["checks"].items() if c["status"] == "fail"])

    def test_crossing_between_fixed_sampling_instants_is_caught(self):
        # envelopes 0.5 + 0.5 mm, passing 0.9999999 mm apart at 200 mm/s each:
        # they overlap for about 2 microseconds
        offset = 0.9999999
        text = job(crossing_body(offset, barrier=False), r0=0.5, r1=0.5)
        mm = mmod.MultiReplay(gr.Options(), text)
        mm.run(text)
        tl = mmod.build_timeline(mm)
        A, B = tl["tracks"]
        for dt in (1e-3, 1e-4, 1e-5):
            t = np.arange(0.0, tl["build_s"], dt)
            ka = np.clip(np.searchsorted(A.t0, t, side="right") - 1, 0, A.n - 1)
            kb = np.clip(np.searchsorted(B.t0, t, side="right") - 1, 0, B.n - 1)
            ax, ay = A.xy(ka, t)
            bx, by = B.xy(kb, t)
            d = np.hypot(ax - bx, ay - by)
            self.assertGreaterEqual(np.nanmin(d), 1.0, f"sampling every {dt} s finds the overlap")
        rep = run(text)
        self.assertEqual(rep["collisions"]["count"], 1)
        self.assertAlmostEqual(rep["collisions"]["examples"][0]["distance_mm"], offset, places=9)
        # the same pass 1.0000001 apart only touches: no collision
        rep = run(job(crossing_body(1.0000001, barrier=False), r0=0.5, r1=0.5))
        self.assertEqual(rep["collisions"]["count"], 0)
        self.assertAlmostEqual(rep["collisions"]["closest_mm"], 1.0000001, places=9)

    def test_collision_while_accelerating_is_exact(self):
        # head 1 waits at (110, 100); head 0 accelerates from rest toward it and stops 2 mm short
        body = "\n".join(["M596 P0", "G0 X50 Y100 F6000", "M596 P1", "G0 U110 V100 F6000", "M598",
                          "M596 P0", "G0 X108 Y100"]) + "\n"
        rep = run(job(body, r0=2.0, r1=2.0))
        ex = rep["collisions"]["examples"]
        self.assertEqual(len(ex), 1)
        self.assertAlmostEqual(ex[0]["distance_mm"], 2.0, places=9)
        self.assertAlmostEqual(ex[0]["positions"]["0"][0], 108.0, places=9)
        # the episode starts when head 0 enters 4 mm (decelerating) and lasts to the end
        self.assertGreater(ex[0]["end_s"] - ex[0]["start_s"], 0.0)

    def test_exact_closest_approach_agrees_with_dense_sampling(self):
        # random short moves at random feeds (many accelerating/braking phases);
        # envelopes so large that every interval is solved exactly
        rng = np.random.default_rng(17)
        body = ["M596 P0", "G0 X100 Y100 F6000", "M596 P1", "G0 U160 V100 F6000", "M598"]
        for sysno, (lx, ly, cx) in enumerate((("X", "Y", 100.0), ("U", "V", 160.0))):
            body.append(f"M596 P{sysno}")
            for _ in range(40):
                x, y = cx + rng.uniform(-25, 25), 100 + rng.uniform(-25, 25)
                body.append(f"G0 {lx}{x:.3f} {ly}{y:.3f} F{rng.uniform(600, 15000):.0f}")
        text = job("\n".join(body) + "\n", r0=500.0, r1=500.0)
        rep = run(text)
        exact = rep["collisions"]["closest_mm"]
        mm = mmod.MultiReplay(gr.Options(), text)
        mm.run(text)
        tl = mmod.build_timeline(mm)
        A, B = tl["tracks"]
        t = np.linspace(0.0, tl["build_s"], 2_000_001)
        ka = np.clip(np.searchsorted(A.t0, t, side="right") - 1, 0, A.n - 1)
        kb = np.clip(np.searchsorted(B.t0, t, side="right") - 1, 0, B.n - 1)
        ax, ay = A.xy(ka, t)
        bx, by = B.xy(kb, t)
        sampled = float(np.nanmin(np.hypot(ax - bx, ay - by)))
        step = t[1] - t[0]
        self.assertLessEqual(exact, sampled + 1e-9)
        self.assertGreater(exact, sampled - 2 * 250.0 * step)  # heads move at most 250 mm/s
        # and the piecewise states agree with the vectorised positions
        for k in range(0, A.n, 7):
            tm = 0.5 * (A.t0[k] + A.t1[k])
            x, y = A.state(k, tm, tm)[:2]
            px, py = A.xy(np.array([k]), np.array([tm]))
            if not math.isnan(x):
                self.assertAlmostEqual(x, float(px[0]), places=6)
                self.assertAlmostEqual(y, float(py[0]), places=6)

    def test_shared_gantry_checks_x_order(self):
        # head 1 passes *over* head 0 in Y far apart in X order terms, but swaps the X order
        body = "\n".join(["M596 P0", "G0 X100 Y20 F6000", "M596 P1", "G0 U200 V280 F6000", "M598",
                          "M596 P1", "G0 U50 V280"]) + "\n"
        discs = run(job(body))
        self.assertEqual(discs["collisions"]["count"], 0)
        gantry = run(job(body), shared_gantry=True)
        self.assertEqual(gantry["collisions"]["mode"], "shared-gantry")
        self.assertEqual(gantry["collisions"]["count"], 1)
        self.assertLess(gantry["collisions"]["examples"][0]["distance_mm"], 10.0)
        # the header line does the same
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("; flavor: rrf\n", "; flavor: rrf\n; machine: shared gantry\n")
        rep = run(job(body, header=header))
        self.assertEqual(rep["collisions"]["mode"], "shared-gantry")
        self.assertEqual(rep["collisions"]["count"], 1)

    def test_no_radius_skips(self):
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace(", envelope 5 mm", "")
        rep = run(job(crossing_body(3.0, barrier=False), header=header))
        self.assertEqual(status(rep, "collisions"), "skipped")
        rep = run(job(crossing_body(3.0, barrier=False), header=header), head_radius=5.0)
        self.assertEqual(rep["collisions"]["count"], 1)
        rep = run(job(crossing_body(3.0, barrier=False), header=header), envelopes={0: 2.0, 1: 1.0 + 1e-6})
        self.assertEqual(rep["collisions"]["count"], 1)
        rep = run(job(crossing_body(3.0, barrier=False), header=header), envelopes={0: 2.0, 1: 1.0 - 1e-6})
        self.assertEqual(rep["collisions"]["count"], 0)


class Timing(unittest.TestCase):
    def test_wrong_time_estimate_fails(self):
        body, _ = clean_layers(layers=2)
        rep = run(job(body, factor=1.05))
        self.assertEqual(status(rep, "time"), "fail")
        self.assertAlmostEqual(rep["time"]["rel_error"], 0.05, places=3)
        self.assertEqual(status(run(job(body, factor=1.015)), "time"), "pass")
        self.assertEqual(status(run(job(body, factor=1.05), time_tol=0.06), "time"), "pass")

    def test_sequential_estimate_fails(self):
        # an estimate that adds the streams up (as if one tool printed at a time) is wrong
        body, _ = clean_layers(layers=2)
        rep = run(job(body, estimate=False))
        seq = sum(r["busy_s"] for r in rep["streams"])
        rep = run(job(body, estimate=seq))
        self.assertEqual(status(rep, "time"), "fail")

    def test_barrier_waits_and_dwells(self):
        body = "\n".join(["M596 P0", "G4 S3", "M596 P1", "G4 S1", "M598", "M596 P1", "G4 S2"]) + "\n"
        rep = run(job(body))
        rows = rep["streams"]
        self.assertAlmostEqual(rep["time"]["replayed_s"], 5.0, places=9)
        self.assertAlmostEqual(rows[0]["wait_s"], 2.0, places=9)
        self.assertAlmostEqual(rows[1]["wait_s"], 2.0, places=9)
        self.assertAlmostEqual(rows[0]["paused_share"], 0.4)
        self.assertAlmostEqual(rows[1]["longest_wait_s"], 2.0)

    def test_busiest_stream_per_layer(self):
        # Each layer: head 0 works while head 1 waits, then the other way round (a
        # job taking the heads one at a time). Side by side, a layer would take its
        # busier head's time: 3 s and 4 s, against 4 s and 5 s replayed.
        body = "\n".join([
            "M596 P0", ";LAYER:0", "G4 S3", "M596 P1", ";LAYER:0", "M598",
            "M596 P1", "G4 S1", "M598",
            "M596 P0", ";LAYER:1", "G4 S1", "M596 P1", ";LAYER:1", "M598",
            "M596 P1", "G4 S4",
        ]) + "\n"
        rep = run(job(body))
        t = rep["time"]
        self.assertAlmostEqual(t["replayed_s"], 9.0, places=9)
        self.assertAlmostEqual(t["streams_sum_s"], 9.0, places=9)
        self.assertAlmostEqual(t["layers_busiest_s"], 7.0, places=9)
        # Dwells are no printing.
        self.assertEqual(t["layers_busiest_print_s"], 0.0)

    def test_busiest_printing_per_layer(self):
        # Both heads print a 40 mm square per layer after a travel to it: per layer,
        # the busier head's printing moves, without the travel. The heads print the
        # same, so over the layers that is about either head's printing (at least the
        # busier head's), and neither both heads' nor the travel.
        body, _ = clean_layers(layers=2)
        rep = run(job(body))
        t = rep["time"]
        prints = [row["by_kind_s"]["print"] for row in rep["streams"]]
        travel = min(row["by_kind_s"]["travel"] for row in rep["streams"])
        self.assertGreater(min(prints), 2 * 160 / 30)  # 160 mm a layer at 30 mm/s
        self.assertGreater(travel, 0.1)
        self.assertGreaterEqual(t["layers_busiest_print_s"], max(prints) - 1e-9)
        self.assertLess(t["layers_busiest_print_s"], max(prints) + 0.01)
        self.assertLess(t["layers_busiest_print_s"] + travel, t["layers_busiest_s"] + 1e-9)

    def test_m400_synchronises(self):
        body = "\n".join(["M596 P0", "G4 S3", "M400", "M596 P1", "G4 S1"]) + "\n"
        self.assertAlmostEqual(run(job(body))["time"]["replayed_s"], 4.0, places=9)
        for sync in ("M400 S1", "G4 P0", "G4 S0"):
            rep = run(job(body.replace("M400", sync)))
            self.assertAlmostEqual(rep["time"]["replayed_s"], 4.0, places=9)
            self.assertEqual(rep["time"]["barrier_kinds"].get("M400 S1", 0) + rep["time"]["barrier_kinds"].get("G4 P0", 0), 1)
        # a dwell of some time is the selected stream's own
        self.assertAlmostEqual(run(job(body.replace("M400", "G4 P250")))["time"]["replayed_s"], 3.25, places=9)


class Heating(unittest.TestCase):
    def test_stream_extruding_with_a_cold_tool_fails(self):
        body, _ = clean_layers(layers=1)
        rep = run(job(body, t1=0))
        self.assertEqual(status(rep, "heating"), "fail")
        msgs = messages(rep, "heating")
        self.assertTrue(all(m.startswith("system 1: ") for m in msgs), msgs)
        self.assertTrue(any("cold extrusion" in m and "T1" in m for m in msgs))
        self.assertEqual(status(run(job(body)), "heating"), "pass")

    def test_wait_in_another_stream_counts_only_after_a_barrier(self):
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("M116 P1\n", "")
        body = ("M596 P0\nM116 P1\nM596 P1\n;LAYER:0\n;TYPE:PART\nG0 U220 V20 F6000\nG1 U240 V20 E1 F1800\n"
                "M598\nG1 U260 V20 E1\n")
        rep = run(job(body, header=header, estimate=False))
        ex = rep["checks"]["heating"]["examples"]
        self.assertEqual(len(ex), 1, ex)
        self.assertIn("before waiting", ex[0]["message"])
        self.assertTrue(ex[0]["message"].startswith("system 1: "))

    def test_tool_of_another_system(self):
        body = "M596 P0\nT1\n"
        rep = run(job(body, estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertTrue(any("T1 selected while motion system 1 holds it" in m for m in messages(rep, "streams")))


# A prologue that heats the bed (M140 ... M190) while it dwells and moves, then
# forks; each stream selects its tool and waits for it (M116 P<n>) on its own.
HEAT_PROLOGUE = """; flavor: rrf
; motion system 0: X axis X, Y axis Y, Z axis Z, envelope 5 mm, home X 0 Y 0
; motion system 1: X axis U, Y axis V, Z axis Z, envelope 5 mm, home X 300 Y 300
G21
G90
M83
M204 P1000 T2000
G92 X0 Y0 Z0
M140 S65
G4 S10
G1 X100 Y0 F6000
M190 S65
G10 P0 S215 R150
G10 P1 S215 R150
G4 S2
"""
HEAT_FORK = """M606 S1
M596 P0
T0
M116 P0
M596 P1
M83
T1
M116 P1
M598
"""
# Lines of the waits above: M190 S65, M116 P0, M116 P1.
BED_WAIT_LINE, WAIT0_LINE, WAIT1_LINE = 12, 19, 23
# From ambient (25 degC) at 2 degC/s to M116's 2 degC below 215 degC.
TOOL_WAIT = (215 - 2 - 25) / 2
# ... where the wait leaves the tool: a raise to 240 degC then waits this long.
RAISE_WAIT = (240 - 2 - 213) / 2


def heated(body: str = "", **kw) -> dict:
    """The report of the heated two-stream job with ``body`` after its first M598."""
    kw.setdefault("heating_rate", 2.0)
    return run(HEAT_PROLOGUE + HEAT_FORK + body + "M598\n", **kw)


class HeatingWaits(unittest.TestCase):
    """The heating model (``--heating-rate``) across the fork and in each stream."""

    def test_prologue_is_timed_as_a_single_stream_file(self):
        single = gr.analyse(HEAT_PROLOGUE, gr.Options(heating_rate=2.0))
        self.assertEqual(single["mode"], "single")
        prologue_s = single["time"]["replayed_s"]
        # The bed heats during the dwell and the move: at 0.5 degC/s to 1 degC below 65
        # it needs 78 s from 25 degC, and M190 waits for what is left; 2 s of dwell after.
        self.assertAlmostEqual(prologue_s, 78 + 2)
        self.assertLess(single["time"]["heating_waits"][0]["wait_s"], 78 - 10 - 0.5)
        rep = heated()
        t = rep["time"]
        first = t["heating_waits"][0]
        self.assertEqual((first["system"], first["line"]), (0, BED_WAIT_LINE))
        self.assertAlmostEqual(first["wait_s"], single["time"]["heating_waits"][0]["wait_s"])
        self.assertAlmostEqual(first["time_s"], 78 - first["wait_s"])
        # Both streams start at the end of the prologue and heat their tools from ambient.
        later = [(w["system"], w["line"]) for w in t["heating_waits"][1:]]
        self.assertEqual(later, [(0, WAIT0_LINE), (1, WAIT1_LINE)])
        for w in t["heating_waits"][1:]:
            self.assertAlmostEqual(w["time_s"], prologue_s)
            self.assertAlmostEqual(w["wait_s"], TOOL_WAIT)
        self.assertAlmostEqual(t["replayed_s"], prologue_s + TOOL_WAIT)
        self.assertAlmostEqual(t["heating_wait_s"], first["wait_s"] + 2 * TOOL_WAIT)
        rows = rep["streams"]
        self.assertAlmostEqual(rows[0]["heating_wait_s"], first["wait_s"] + TOOL_WAIT)
        self.assertAlmostEqual(rows[1]["heating_wait_s"], TOOL_WAIT)
        self.assertIsNotNone(t["heating_model"])
        self.assertEqual(t["heating_model"]["heating_rate"], 2.0)
        self.assertEqual(status(rep, "heating"), "pass")
        self.assertFalse(any("not modelled" in w for w in rep["warnings"]), rep["warnings"])
        self.assertIn(f"heating waits {t['heating_wait_s']:.1f} s", mmod.summary_multi(rep))

    def test_the_tracks_stand_still_while_waiting(self):
        mm = mmod.MultiReplay(gr.Options(heating_rate=2.0), HEAT_PROLOGUE + HEAT_FORK)
        mm.run(HEAT_PROLOGUE + HEAT_FORK)
        tl = mmod.build_timeline(mm)
        for s, tr in enumerate(tl["tracks"]):
            self.assertAlmostEqual(tr.t1[-1], tl["build_s"])
            self.assertTrue(np.allclose(tr.t0[1:], tr.t1[:-1]))  # contiguous
            heat = tr.kind == 3
            self.assertAlmostEqual(float((tr.t1 - tr.t0)[heat].sum()), tl["streams"][s]["heating_wait_s"])
            self.assertEqual(int(tr.line[heat][-1]), (WAIT0_LINE, WAIT1_LINE)[s])

    def test_a_wait_in_one_stream_delays_the_barrier(self):
        base = heated()["time"]["replayed_s"]
        # Stream 1 raises its tool to 240 degC and waits 12.5 s; stream 0 travels 100 mm
        # meanwhile and then waits at the M598 for stream 1.
        body = "M596 P0\nG1 X200 Y0 F6000\nM596 P1\nG10 P1 S240\nM116 P1\nM598\nM596 P0\nG4 S1\n"
        rep = heated(body)
        t = rep["time"]
        self.assertEqual([(w["system"], w["line"]) for w in t["heating_waits"]][-1], (1, 29))
        self.assertAlmostEqual(t["heating_waits"][-1]["wait_s"], RAISE_WAIT)
        self.assertAlmostEqual(t["heating_waits"][-1]["time_s"], base)
        self.assertAlmostEqual(t["replayed_s"], base + RAISE_WAIT + 1.0)
        # stream 0's travels: 100 mm in the prologue and 100 mm here, from rest to rest
        travel = rep["streams"][0]["by_kind_s"]["travel"] / 2
        self.assertGreater(travel, 0.5)
        self.assertAlmostEqual(rep["streams"][0]["longest_wait_s"], RAISE_WAIT - travel)
        # Without the model the streams wait for nothing: the dwells and the travels.
        off = heated(body, heating_rate=None)["time"]
        self.assertAlmostEqual(off["replayed_s"], 10 + travel + 2 + travel + 1.0)

    def test_each_stream_heats_with_its_own_commands(self):
        # Stream 0 raises T0 and waits for it; stream 1 only waits for T1, which is at its
        # target: stream 0's raise does not lengthen stream 1's wait.
        body = "M596 P0\nG10 P0 S240\nM116 P0\nM596 P1\nM116 P1\n"
        rep = heated(body)
        late = [w for w in rep["time"]["heating_waits"] if w["line"] > 24]
        self.assertEqual([(w["system"], w["line"]) for w in late], [(0, 27)])
        self.assertAlmostEqual(late[0]["wait_s"], RAISE_WAIT)
        self.assertAlmostEqual(rep["time"]["replayed_s"], 80 + TOOL_WAIT + RAISE_WAIT)
        self.assertFalse(any("not modelled" in w for w in rep["warnings"]), rep["warnings"])

    def test_heater_of_both_streams_warns_and_waits_on_the_waiting_stream(self):
        # The bed (65 degC since the prologue): stream 1 raises it to 80 and waits,
        # stream 0 switches it off meanwhile. Stream 1's wait sees its own target only.
        body = "M596 P0\nG4 S5\nM140 S0\nM596 P1\nG4 S3\nM190 S80\n"
        rep = heated(body)
        t = rep["time"]
        bed = t["heating_waits"][-1]
        self.assertEqual((bed["system"], bed["line"]), (1, 30))
        self.assertAlmostEqual(bed["wait_s"], (80 - 1 - 65) / 0.5)
        self.assertAlmostEqual(bed["time_s"], 80 + TOOL_WAIT + 3)
        self.assertAlmostEqual(t["replayed_s"], 80 + TOOL_WAIT + 3 + bed["wait_s"])
        warn = [w for w in rep["warnings"] if "not modelled" in w]
        self.assertEqual(len(warn), 1, rep["warnings"])
        self.assertIn("the bed", warn[0])
        self.assertIn("motion system 0 (line 27) and motion system 1 (line 30)", warn[0])

    def test_tool_changes_and_waits_in_a_stream(self):
        # Stream 1 changes from T1 to T2 (5 s, then T2 heats from ambient) and waits.
        body = "M596 P1\nG10 P2 S200 R150\nT2\nM116 P2\n"
        rep = heated(body, tool_change_time=5.0)
        t = rep["time"]
        self.assertEqual(t["tool_change_s"], 5.0)
        self.assertAlmostEqual(t["heating_waits"][-1]["wait_s"], (200 - 2 - 25) / 2)
        self.assertAlmostEqual(t["heating_waits"][-1]["time_s"], 80 + TOOL_WAIT + 5.0)
        self.assertAlmostEqual(t["replayed_s"], 80 + TOOL_WAIT + 5.0 + (200 - 2 - 25) / 2)

    def test_off_without_a_heating_rate(self):
        rep = heated(heating_rate=None)
        t = rep["time"]
        self.assertEqual(t["heating_wait_s"], 0.0)
        self.assertEqual(t["heating_waits"], [])
        self.assertIsNone(t["heating_model"])
        self.assertAlmostEqual(t["replayed_s"], 10 + 2 + rep["streams"][0]["by_kind_s"]["travel"])
        mm = mmod.MultiReplay(gr.Options(), HEAT_PROLOGUE + HEAT_FORK)
        mm.run(HEAT_PROLOGUE + HEAT_FORK)
        self.assertFalse(any(e[0] == "h" for st in mm.streams for e in st.events))


class FirmwareRules(unittest.TestCase):
    def test_unforked_job_fails(self):
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("M606 S1\n", "")
        rep = run(job("", header=header, estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertIn("before M606 S1", messages(rep, "streams")[0])

    def test_axis_owned_by_another_system(self):
        # system 1 names Z (which system 0 took at its layer change) before any release
        body = "M596 P0\nG1 Z0.4 F600\nM596 P1\nG0 U220 V20 Z0.6 F6000\n"
        rep = run(job(body, estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertTrue(any("axis Z, owned by motion system 0" in m for m in messages(rep, "streams")))
        # after M598 the axis is free again
        ok = run(job(body.replace("M596 P1\n", "M598\nM596 P1\n"), estimate=False))
        self.assertEqual(status(ok, "streams"), "pass", ok["checks"]["streams"])

    def test_m400_s1_keeps_the_axes(self):
        body = "M596 P0\nG1 Z0.4 F600\nM400 S1\nM596 P1\nG0 U220 V20 Z0.6 F6000\n"
        rep = run(job(body, estimate=False))
        self.assertTrue(any("axis Z, owned by motion system 0" in m for m in messages(rep, "streams")))
        ok = run(job(body.replace("M400 S1", "M400"), estimate=False))
        self.assertEqual(status(ok, "streams"), "pass", ok["checks"]["streams"])

    def test_idex_heads_sharing_y_cannot_print_concurrently(self):
        body, _ = clean_layers(layers=1)
        body = body.replace(" V", " Y")
        rep = run(job(body, estimate=False), axis_maps={1: {"X": "U", "Y": "Y"}})
        self.assertEqual(rep["motion_systems"]["shared_axes"], ["Y", "Z"])
        msgs = messages(rep, "streams")
        self.assertTrue(any("moves axis Y, owned by motion system 0" in m for m in msgs), msgs)
        self.assertTrue(any("moves shared axis Y" in m for m in msgs), msgs)

    def test_third_motion_system(self):
        rep = run(job("M596 P2\nG4 S1\n", estimate=False))
        self.assertTrue(any("two motion systems" in m for m in messages(rep, "streams")))
        self.assertEqual(len(rep["streams"]), 3)

    def test_shared_z_moving_under_an_extruding_head(self):
        body, _ = clean_layers(layers=2)
        unsynced = body.replace("G1 Z0.400 F600\nM598\n", "G1 Z0.400 F600\n")
        rep = run(job(unsynced, estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertTrue(any("moves shared axis Z" in m and "motion system 1 moves filament" in m
                            for m in messages(rep, "streams")))

    def test_forked_stream_sets_its_own_extrusion_mode(self):
        body, _ = clean_layers(layers=1)
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("M596 P1\nM83\n", "M596 P1\n")
        rep = run(job(body, header=header, estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertEqual(rep["checks"]["streams"]["violations"], 1)
        self.assertIn("system 1: moves filament before setting its extrusion mode", messages(rep, "streams")[0])
        # replayed as absolute E: the repeated E2.0 of stream 1 pushes filament once
        self.assertAlmostEqual(rep["extrusion"]["filament_mm"]["T1"], 2.0)

    def test_foreign_axis_letter(self):
        rep = run(job("M596 P1\nG0 X20 Y20\n", estimate=False))
        self.assertEqual(status(rep, "streams"), "fail")
        self.assertEqual(rep["checks"]["streams"]["violations"], 2)
        self.assertIn("names axis X", messages(rep, "streams")[0])

    def test_m597_blocks(self):
        # M597 X0 U20: U must stay 20 mm above X within each block between synchronisation points
        body = ("M597 X0 U20\nM596 P0\nG0 X100 Y20 F6000\nM596 P1\nG0 U130 V280 F6000\nM598\n"
                "M596 P0\nG0 X115\n")
        rep = run(job(body, estimate=False))
        self.assertEqual(status(rep, "separation"), "fail")
        self.assertEqual(rep["checks"]["separation"]["examples"][0]["line"], len(HEADER.splitlines()) + 8)
        # the same positions one block later are fine when head 1 moved away first
        ok = run(job(body.replace("M596 P0\nG0 X115\n", "M596 P1\nG0 U140\nM598\nM596 P0\nG0 X115\n"),
                     estimate=False))
        self.assertEqual(status(ok, "separation"), "pass")


class PlannedExtrusion(unittest.TestCase):
    def test_planned_volumes_per_tool(self):
        body, fil = clean_layers(layers=2)
        v0, v1 = fil["T0"] * FIL_AREA, fil["T1"] * FIL_AREA
        good = f"; planned extrusion T0: {v0 * 1.005:.4f} mm3\n; planned extrusion T1: {v1 * 0.995:.4f} mm3\n"
        rep = run(job(body, extra_footer=good))
        self.assertEqual(status(rep, "extrusion"), "pass", rep["checks"]["extrusion"])
        self.assertAlmostEqual(rep["extrusion"]["rel_error"]["T0"], 1 / 1.005 - 1, places=5)
        bad = f"; planned extrusion T0: {v0 * 1.02:.4f} mm3\n; planned extrusion T1: {v1:.4f} mm3\n"
        rep = run(job(body, extra_footer=bad))
        self.assertEqual(status(rep, "extrusion"), "fail")
        self.assertEqual(rep["checks"]["extrusion"]["violations"], 1)
        self.assertIn("T0", messages(rep, "extrusion")[0])


class MeshChecks(unittest.TestCase):
    def test_volume_and_coverage_merge_the_streams(self):
        w, h, size = 0.4, 0.2, 10.0
        n = int(size / w)
        body = []
        for li in range(3):
            z = h * (li + 1)
            body += ["M596 P0", f"G1 Z{z:.3f} F600", "M598"]
            # rasters 0..12 by system 0, 13..24 by system 1 (after a barrier: same area of the bed)
            for sysno, ks, (lx, ly) in ((0, range(0, 13), ("X", "Y")), (1, range(13, n), ("U", "V"))):
                body += [f"M596 P{sysno}", f";LAYER:{li}", ";TYPE:PART"]
                for k in ks:
                    y = 95 + w / 2 + k * w
                    body.append(f"G0 {lx}95.0000 {ly}{y:.4f} F6000")
                    body.append(f"G1 {lx}105.0000 {ly}{y:.4f} E{w * h * size / FIL_AREA:.6f} F1800")
                body.append("M598")
                if sysno == 0:
                    body += ["G0 X20 Y20"]
                    body.append("M598")
        with tempfile.TemporaryDirectory() as tmp:
            stl = os.path.join(tmp, "box.stl")
            tg.write_box_stl(stl, sz=0.6)
            rep = run(job("\n".join(body) + "\n", r0=1.0, r1=1.0), mesh=stl, place="100,100",
                      coverage_every=1)
        self.assertEqual(status(rep, "volume"), "pass", rep["checks"]["volume"])
        self.assertAlmostEqual(rep["volume"]["ratio"], 1.0, places=4)
        self.assertEqual(status(rep, "coverage"), "pass", rep["checks"]["coverage"])
        self.assertEqual(len(rep["coverage"]["layers"]), 3)
        for row in rep["coverage"]["layers"]:
            self.assertGreater(row["coverage"], 0.9999)
            self.assertLess(row["overlap"], 1e-4)
        self.assertEqual(status(rep, "collisions"), "pass", rep["collisions"]["examples"][:1])


class MachineState(unittest.TestCase):
    """Per-system settings, the end state and waits with a loaded nozzle."""

    def test_m204_and_axis_limits_are_per_system(self):
        body, _ = clean_layers(layers=1)
        self.assertEqual(status(run(job(body)), "settings"), "pass")
        # Without system 1's own M204 it runs at the firmware's accelerations.
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("M83\nM204 P1000 T2000\nT1", "M83\nT1")
        rep = run(job(body, header=header))
        self.assertEqual(status(rep, "settings"), "fail")
        self.assertIn("motion system 1", messages(rep, "settings")[0])
        # Axis limits naming X and Y only leave U and V at the defaults.
        xy = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace("G21\n", "G21\nM201 X3000 Y3000 Z200 E3000\n")
        rep = run(job(body, header=xy))
        self.assertEqual(status(rep, "settings"), "fail")
        self.assertTrue(any("axis U" in m for m in messages(rep, "settings")))
        uv = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace(
            "G21\n", "G21\nM201 X3000 Y3000 U3000 V3000 Z200 E3000\n")
        self.assertEqual(status(run(job(body, header=uv)), "settings"), "pass")

    def test_a_heater_left_on_fails_the_end(self):
        body, _ = clean_layers(layers=1)
        text = job(body).replace("M568 P1 S0 R0 A0\n", "")
        rep = run(text)
        self.assertEqual(status(rep, "end"), "fail")
        self.assertIn("heater 1", messages(rep, "end")[0])

    def test_m568_a2_heats_a_tool_without_selecting_it(self):
        text = ("; flavor: rrf\nG21\nG90\nM83\nG10 P0 S210 R150\nM568 P0 A2\nM116\nT0\n"
                ";LAYER:0\n;TYPE:PART\nG1 X10 Y10 Z0.2 F600\nG1 X20 Y10 E0.5 F1200\n")
        self.assertEqual(run(text)["checks"]["heating"]["status"], "pass")
        # Without A2 the tool heats only when selected, after the wait.
        rep = run(text.replace("M568 P0 A2\n", ""))
        self.assertEqual(rep["checks"]["heating"]["status"], "fail")

    def test_a_barrier_reached_with_a_loaded_nozzle_fails(self):
        body, _ = clean_layers(layers=2)
        self.assertEqual(status(run(job(body)), "waits"), "pass")
        rep = run(job(body.replace("G1 E-1 F2400\n", "")))
        self.assertEqual(status(rep, "waits"), "fail")
        self.assertGreater(rep["checks"]["waits"]["loaded_barriers"], 0)

    def test_a_slower_system_shifts_the_release_times(self):
        body, _ = clean_layers(layers=2)
        base = run(job(body, estimate=False))
        slow = run(job(body, estimate=False), perturb={1: (0.8, 1.0)})
        self.assertGreater(slow["streams"][1]["busy_s"], base["streams"][1]["busy_s"] * 1.1)
        self.assertAlmostEqual(slow["streams"][0]["busy_s"], base["streams"][0]["busy_s"], places=9)

    def test_dual_gantry_checks_y_order(self):
        # Head 1 moves in front of head 0, far away in X: discs pass, gantries do not.
        body = "\n".join(["M596 P0", "G0 X20 Y100 F6000", "M596 P1", "G0 U250 V200 F6000", "M598",
                          "M596 P1", "G0 U250 V50"]) + "\n"
        self.assertEqual(run(job(body))["collisions"]["count"], 0)
        header = HEADER.format(r0=5, r1=5, t0=210, t1=210).replace(
            "; flavor: rrf\n", "; flavor: rrf\n; machine: dual gantry\n")
        rep = run(job(body, header=header))
        self.assertEqual(rep["collisions"]["mode"], "dual-gantry")
        self.assertEqual(rep["collisions"]["count"], 1)
        self.assertLess(rep["collisions"]["examples"][0]["distance_mm"], 10.0)


class HeaderAndCli(unittest.TestCase):
    def test_header_parse(self):
        systems, gantry, warns = mmod.parse_header(
            "; motion system 1: X axis U, Y axis V, envelope 4.5 mm, home X 300 Y -2\n"
            "; machine: motion system 0: X axis X, Y axis Y, envelope 4 mm\n; machine: shared gantry\n"
            "; motion system 2: X axis W, colour blue\n")
        self.assertEqual(systems[1]["axes"], {"X": "U", "Y": "V"})
        self.assertEqual(systems[1]["radius"], 4.5)
        self.assertEqual(systems[1]["home"], (300.0, -2.0))
        self.assertEqual(systems[0]["radius"], 4.0)
        self.assertTrue(gantry)
        self.assertEqual(len(warns), 1)

    def test_options_override_header(self):
        rep = run(job(crossing_body(3.0, barrier=False)), axis_maps={1: {"X": "U", "Y": "V"}}, head_radius=1.0)
        systems = rep["motion_systems"]["systems"]
        self.assertEqual(systems[1]["from"]["radius"], "option --head-radius")
        self.assertEqual(systems[1]["from"]["axes"], "option --axis-map")
        self.assertEqual(rep["collisions"]["count"], 0)  # 3 mm apart, envelopes 1 + 1

    def test_cli(self):
        path, o, _ = gr.parse_args(["f.gcode", "--head-radius", "4", "--envelope", "1:6.5", "--axis-map",
                                    "1:X=U,Y=v", "--home", "1:300,-5", "--shared-gantry", "--time-tol", "0.03"])
        self.assertEqual(o.head_radius, 4.0)
        self.assertEqual(o.envelopes, {1: 6.5})
        self.assertEqual(o.axis_maps, {1: {"X": "U", "Y": "V"}})
        self.assertEqual(o.homes, {1: (300.0, -5.0)})
        self.assertTrue(o.shared_gantry)
        self.assertEqual(o.time_tol, 0.03)
        self.assertIsNone(gr.parse_args(["f.gcode"])[1].time_tol)
        with tempfile.TemporaryDirectory() as tmp:
            g = os.path.join(tmp, "mm.gcode")
            j = os.path.join(tmp, "mm.json")
            with open(g, "w") as fh:
                fh.write(job(crossing_body(3.0, barrier=False)))
            out = io.StringIO()
            with redirect_stdout(out):
                rc = gr.main([g, "--json", j])
            self.assertEqual(rc, 1)
            self.assertIn("collisions (discs): 1", out.getvalue())
            self.assertIn("RESULT: FAIL", out.getvalue())
            with open(j) as fh:
                rep = json.load(fh)
            for key in ("mode", "motion_systems", "streams", "time", "extrusion", "collisions", "checks", "tools"):
                self.assertIn(key, rep)
            with open(g, "w") as fh:
                fh.write(job(crossing_body(3.0, barrier=True)))
            with redirect_stdout(io.StringIO()):
                self.assertEqual(gr.main([g, "--json", j]), 0)

    def test_single_stream_files_are_unchanged(self):
        rep = run("; flavor: rrf\nG90\nM83\nG0 X0 Y0 F6000\nG0 X100\n")
        self.assertEqual(rep["mode"], "single")
        self.assertEqual(rep["options"]["time_tol"], 0.05)


if __name__ == "__main__":
    unittest.main()
