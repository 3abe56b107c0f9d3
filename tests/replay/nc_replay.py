#!/usr/bin/env python3
"""Replays an NC file for a hybrid cell as a LinuxCNC-style controller reads it.

Every line is parsed by pygcode, a third-party RS-274/NGC parser; the state machine
below follows the RS-274/NGC semantics of the LinuxCNC G-code reference:

- G21/G20 units, G90/G91 distance mode, G94 feed per minute; a feed move (G1) needs a
  feed rate (F) set before it;
- T<n> selects a tool, M6 loads it; G43 H<n> applies the loaded tool's length offset;
- M3/M4 start the spindle at the S word's speed, M5 stops it; a laser driven as a
  spindle takes its power from the S word;
- M64 P<n> / M65 P<n> switch digital output n on and off;
- M0 pauses for the operator; M2/M30 end the program.

The caller says what each tool number is (`--tool 1=end-mill ...`) and which digital
outputs drive the spray gun and the filler (`--spray-output`, `--fill-output`). A feed
move in XY is *working* when its tool works: a rotating tool (end-mill,
grinding-wheel) with the spindle on at a speed above zero, a laser with M3 and a power
above zero, the spray gun or the filler with its output on.

Checks (each violation names its line):
- no motion before millimetres and absolute mode are set;
- no feed move without a feed rate;
- no tool change while the spindle turns;
- every feed move with the length offset of the loaded tool;
- every feed move in XY works (a tool that is off does not crawl over the part);
- no rapid move in XY while the spray, the filler or the laser is on;
- no rapid move (in XY or down) ending below the highest height a rotating tool has
  worked at, which is where the part's surface stands;
- the program ends (M2/M30) with the spindle stopped and every output off.

Prints a JSON report: the working length per tool number (mm), the tool changes, the
pauses, and the violations. Exit status 0 when there is none, 1 otherwise, 2 when the
file cannot be read.
"""

import argparse
import json
import math
import sys

try:
    from pygcode import Line
except ImportError:  # pragma: no cover - the caller checks first
    print("pygcode is not installed (pip install pygcode)", file=sys.stderr)
    sys.exit(2)

ROTATING = {"end-mill", "grinding-wheel"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--tool", action="append", default=[], help="N=KIND")
    ap.add_argument("--spray-output", type=int, default=0)
    ap.add_argument("--fill-output", type=int, default=1)
    args = ap.parse_args()
    kinds = {}
    for t in args.tool:
        n, k = t.split("=", 1)
        kinds[int(n)] = k

    state = {
        "mm": False,
        "absolute": False,
        "feed": None,
        "selected": None,
        "loaded": None,
        "offset": None,
        "spindle": False,
        "speed": 0.0,
        "outputs": set(),
        "pos": [None, None, None],
        "top": -math.inf,
        "ended": False,
    }
    lengths = {}
    violations = []
    changes = 0
    pauses = 0

    def bad(n, msg):
        if len(violations) < 50:
            violations.append(f"line {n}: {msg}")

    def working(tool):
        kind = kinds.get(tool)
        if kind in ROTATING or kind == "laser":
            return state["spindle"] and state["speed"] > 0
        if kind == "spray":
            return args.spray_output in state["outputs"]
        if kind == "dispenser":
            return args.fill_output in state["outputs"]
        return False

    try:
        text = open(args.file, encoding="utf-8").read().splitlines()
    except OSError as e:
        print(f"{args.file}: {e}", file=sys.stderr)
        return 2
    for n, raw in enumerate(text, 1):
        try:
            line = Line(raw)
        except Exception as e:  # pygcode raises its own exception types
            print(f"{args.file}:{n}: parse error: {e}", file=sys.stderr)
            return 2
        for g in line.block.gcodes:
            name = type(g).__name__
            word = str(g.word)
            if name == "GCodeUseMillimeters":
                state["mm"] = True
            elif name == "GCodeAbsoluteDistanceMode":
                state["absolute"] = True
            elif name == "GCodeFeedRate":
                state["feed"] = float(g.word.value)
            elif name == "GCodeSpindleSpeed":
                state["speed"] = float(g.word.value)
            elif name == "GCodeSelectTool":
                state["selected"] = int(g.word.value)
            elif name == "GCodeToolChange":
                if state["spindle"]:
                    bad(n, "tool change while the spindle turns")
                state["loaded"] = state["selected"]
                state["offset"] = None
                changes += 1
            elif name == "GCodeToolLengthOffset":
                state["offset"] = int(g.params["H"].value) if "H" in g.params else None
            elif name in ("GCodeStartSpindleCW", "GCodeStartSpindleCCW"):
                state["spindle"] = True
            elif name == "GCodeStopSpindle":
                state["spindle"] = False
            elif name == "GCodeDigitalOutputOn":
                state["outputs"].add(int(g.params["P"].value))
            elif name == "GCodeDigitalOutputOff":
                state["outputs"].discard(int(g.params["P"].value))
            elif name in ("GCodePauseProgram",):
                pauses += 1
            elif word in ("M02", "M30") or name.startswith("GCodeEndProgram"):
                state["ended"] = True
        # Motion after the modal words of the line (speed, feed) are set.
        for g in line.block.gcodes:
            name = type(g).__name__
            if name not in ("GCodeRapidMove", "GCodeLinearMove"):
                continue
            if not (state["mm"] and state["absolute"]):
                bad(n, "motion before G21 and G90")
            target = list(state["pos"])
            for i, axis in enumerate("XYZ"):
                if axis in g.params:
                    target[i] = float(g.params[axis].value)
            moves_xy = any(
                a in g.params and state["pos"][i] is not None and abs(target[i] - state["pos"][i]) > 1e-9
                for i, a in enumerate("XY")
            )
            tool = state["loaded"]
            kind = kinds.get(tool)
            if name == "GCodeLinearMove":
                if not state["feed"]:
                    bad(n, "feed move without a feed rate")
                if state["offset"] != tool:
                    bad(n, f"feed move with the length offset of H{state['offset']}, tool {tool} loaded")
                if moves_xy:
                    if working(tool):
                        d = math.hypot(target[0] - state["pos"][0], target[1] - state["pos"][1])
                        lengths[tool] = lengths.get(tool, 0.0) + d
                        if kind in ROTATING and target[2] is not None:
                            state["top"] = max(state["top"], target[2])
                    else:
                        bad(n, f"feed move in XY with tool {tool} ({kind}) not working")
            else:
                if moves_xy and kind in ("spray", "dispenser", "laser") and working(tool):
                    bad(n, f"rapid move with the {kind} on")
                # A rapid move, across or down, ends above every surface worked so far.
                if target[2] is not None and target[2] < state["top"] - 1e-9:
                    bad(n, f"rapid move to Z{target[2]} below the surface at {state['top']}")
            state["pos"] = target
    if not state["ended"]:
        bad(len(text), "the program does not end with M2 or M30")
    if state["spindle"] or state["outputs"]:
        bad(len(text), "the program ends with the spindle or an output on")
    report = {
        "lengths": {str(k): v for k, v in sorted(lengths.items())},
        "tool_changes": changes,
        "pauses": pauses,
        "lines": len(text),
        "violations": violations,
    }
    print(json.dumps(report))
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
