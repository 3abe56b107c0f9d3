#!/usr/bin/env python3
"""Replays an NC file for a hybrid machine as a LinuxCNC-style controller reads it.

Every line is parsed by pygcode, a third-party RS-274/NGC parser (a line it cannot read
is a violation); the state machine below follows the RS-274/NGC semantics of the
LinuxCNC 2.9 G-code reference:

- G21/G20 units, G90/G91 distance mode, G94 feed per minute; a feed move (G1) needs a
  feed rate (F) set before it;
- T<n> selects a tool, M6 loads it; G43 H<n> applies the loaded tool's length offset,
  G49 cancels it; G53 makes the line's move in machine coordinates;
- M3/M4 start the spindle at the S word's speed, M5 stops it; a laser driven as a
  spindle takes its power from the S word;
- M64 P<n> / M65 P<n> switch digital output n on and off; M67/M68 E<n> Q<v> set analog
  output n to v;
- M0 pauses for the operator; M2/M30 end the program.

The machine is read from its profile (`--machine FILE.toml`, as the `nc` output names it):
the tools' numbers and kinds, the digital outputs of the spray gun and the filler, the
feeders' analog outputs and scale, the motion limits. Without one, `--tool N=KIND`
says what each tool number is. A feed move in XY is *working* when its tool works: a
rotating tool with the spindle on at a speed above zero, a laser with M3 and a power
above zero, the spray gun or the filler with its output on.

Checks (each violation names its line):
- every line parses; no motion before millimetres and absolute mode are set;
- no feed move without a feed rate;
- no tool change while the spindle turns, and every tool change at the safe height:
  after a move to Z 0 in machine coordinates (G53), with no move in between;
- every feed move with the length offset of the loaded tool;
- every feed move in XY works (a tool that is off does not crawl over the part);
- no rapid move in XY while the spray, the filler or the laser is on;
- no rapid move of a tool that touches the work (a rotating tool, the filler) ending
  below the highest height a rotating tool has worked at, where the stock stands;
- the program ends (M2/M30) after the last move, with the spindle stopped, every
  output off and the head at the safe height.

Counted, not judged (the caller compares them with its targets): moves to where the
tool already is, vertical plunges of rotating tools (a feed move down with no move
in XY), the laser's Z cycles (the head going up, then down again, with the laser
loaded) per layer, and per layer (`(layer ...)` comments) the lowest Z of each tool
kind and the feeder values in force each time the spray gun opens.

The cycle time follows the controller's limits: each move's speed is the feed (or the
rapids' speed) capped so no axis exceeds its own rapid speed, its acceleration the most
each axis allows along the move, on a trapezoidal profile. Rapids start and end at
rest; consecutive feed moves run through their corners at the speed the profile's
`junction_deviation` allows (Grbl's junction-deviation rule), and stop at any line that
does something else; plus the profile's seconds per tool change and per spindle start.

Tool kinds known: end-mill and grinding-wheel (rotating), laser, spray, dispenser.

Prints a JSON report. Exit status 0 when there is no violation, 1 otherwise, 2 when
the file cannot be read.
"""

import argparse
import json
import math
import sys
import tomllib

try:
    from pygcode import Line
except ImportError:  # pragma: no cover - the caller checks first
    print("pygcode is not installed (pip install pygcode)", file=sys.stderr)
    sys.exit(2)

ROTATING = {"end-mill", "grinding-wheel"}
KINDS = sorted(ROTATING | {"laser", "spray", "dispenser"})


def chain_time(moves, deviation):
    """Seconds for consecutive feed moves that start and end at rest.

    Each move is (length, cruise speed, acceleration, unit vector). A corner is taken
    at the speed whose circle, tangent to both moves, passes `deviation` from the
    corner at the acceleration's centripetal limit (the junction-deviation rule in
    Grbl's planner documentation); then a backward and a forward pass keep every speed
    reachable from its neighbours within each move's length.
    """
    if not moves:
        return 0.0
    limit = [0.0] * (len(moves) + 1)
    for k in range(1, len(moves)):
        (_, v_prev, a_prev, u_prev), (_, v_next, a_next, u_next) = moves[k - 1], moves[k]
        cos_theta = -sum(p * q for p, q in zip(u_prev, u_next))
        if deviation <= 0 or cos_theta > 0.999999:
            corner = 0.0
        elif cos_theta < -0.999999:
            corner = math.inf
        else:
            half = math.sqrt(0.5 * (1.0 - cos_theta))
            corner = math.sqrt(min(a_prev, a_next) * deviation * half / (1.0 - half))
        limit[k] = min(corner, v_prev, v_next)
    for k in reversed(range(len(moves))):
        length, _, accel, _ = moves[k]
        limit[k] = min(limit[k], math.sqrt(limit[k + 1] ** 2 + 2 * accel * length))
    for k in range(len(moves)):
        length, _, accel, _ = moves[k]
        limit[k + 1] = min(limit[k + 1], math.sqrt(limit[k] ** 2 + 2 * accel * length))
    total = 0.0
    for k, (length, cruise, accel, _) in enumerate(moves):
        v0, v1 = limit[k], limit[k + 1]
        top = math.sqrt((2 * accel * length + v0 * v0 + v1 * v1) / 2)
        if top <= cruise:
            total += (max(top - v0, 0.0) + max(top - v1, 0.0)) / accel
        else:
            ramps = (cruise * cruise - v0 * v0 + cruise * cruise - v1 * v1) / (2 * accel)
            total += (2 * cruise - v0 - v1) / accel + (length - ramps) / cruise
    return total


def trapezoid(length, v, a):
    if length <= 0:
        return 0.0
    if length >= v * v / a:
        return length / v + v / a
    return 2.0 * math.sqrt(length / a)


def main():
    ap = argparse.ArgumentParser(
        description="Replays a hybrid machine's NC file and checks it.",
        epilog="Tool kinds known: " + ", ".join(KINDS) + ".",
    )
    ap.add_argument("file")
    ap.add_argument("--machine", help="the machine's profile (TOML): tools, outputs, feeders, motion")
    ap.add_argument("--tool", action="append", default=[], help="N=KIND, KIND one of " + ", ".join(KINDS))
    ap.add_argument("--spray-output", type=int, default=0)
    ap.add_argument("--fill-output", type=int, default=1)
    args = ap.parse_args()
    kinds = {}
    feeders = {}
    scale = 1.0
    motion = None
    spray_out, fill_out = args.spray_output, args.fill_output
    if args.machine:
        with open(args.machine, "rb") as f:
            profile = tomllib.load(f)
        for t in profile.get("tools", []):
            kinds[int(t["number"])] = t["kind"]
        outs = profile.get("outputs", {})
        spray_out = outs.get("spray", spray_out)
        fill_out = outs.get("filler", fill_out)
        fd = profile.get("feeders", {})
        feeders = {int(n): m for m, n in fd.get("outputs", {}).items()}
        scale = float(fd.get("scale", 1.0))
        motion = profile.get("motion")
    for t in args.tool:
        n, k = t.split("=", 1)
        if k not in KINDS:
            print(f"--tool {t}: unknown kind {k} (known: {', '.join(KINDS)})", file=sys.stderr)
            return 2
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
        "analog": {},
        "pos": [None, None, None],
        "top": -math.inf,
        "ended": False,
        "safe": False,
    }
    lengths = {}
    violations = []
    changes = 0
    changes_safe = 0
    pauses = 0
    noop = 0
    plunges = 0
    time = 0.0
    layers = []
    layer = None
    laser_rising = False
    chain = []
    deviation = float(motion.get("junction_deviation", 0.0)) if motion else 0.0

    def bad(n, msg):
        if len(violations) < 50:
            violations.append(f"line {n}: {msg}")

    def working(tool):
        kind = kinds.get(tool)
        if kind in ROTATING or kind == "laser":
            return state["spindle"] and state["speed"] > 0
        if kind == "spray":
            return spray_out in state["outputs"]
        if kind == "dispenser":
            return fill_out in state["outputs"]
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
            bad(n, f"pygcode cannot read it: {e}")
            continue
        if state["ended"] and line.block.gcodes:
            bad(n, "a command after the program's end")
        comment = line.comment.text if line.comment else ""
        # Feed moves run on through their corners until a line does anything else.
        names = [type(g).__name__ for g in line.block.gcodes]
        if names and any(nm not in ("GCodeLinearMove", "GCodeFeedRate") for nm in names):
            time += chain_time(chain, deviation)
            chain = []
        if comment.startswith("layer "):
            layer = {"label": comment[6:], "lowest": {}, "sprays": [], "laser_z_cycles": 0}
            layers.append(layer)
        machine = any(type(g).__name__ == "GCodeMoveInMachineCoords" for g in line.block.gcodes)
        for g in line.block.gcodes:
            name = type(g).__name__
            word = str(g.word)
            if name == "GCodeUseMillimeters":
                state["mm"] = True
            elif name == "GCodeAbsoluteDistanceMode":
                state["absolute"] = True
            elif name == "GCodeIncrementalDistanceMode":
                state["absolute"] = False
            elif name == "GCodeFeedRate":
                state["feed"] = float(g.word.value)
            elif name == "GCodeSpindleSpeed":
                state["speed"] = float(g.word.value)
            elif name == "GCodeSelectTool":
                state["selected"] = int(g.word.value)
            elif name == "GCodeToolChange":
                if state["spindle"]:
                    bad(n, "tool change while the spindle turns")
                if state["safe"]:
                    changes_safe += 1
                else:
                    bad(n, "tool change away from the safe height (no G53 Z0 just before)")
                state["loaded"] = state["selected"]
                state["offset"] = None
                changes += 1
                if motion:
                    time += float(motion.get("tool_change", 0.0))
            elif name == "GCodeToolLengthOffset":
                state["offset"] = int(g.params["H"].value) if "H" in g.params else None
            elif name == "GCodeCancelToolLengthOffset":
                state["offset"] = None
            elif name in ("GCodeStartSpindleCW", "GCodeStartSpindleCCW"):
                if not state["spindle"] and motion and kinds.get(state["loaded"]) in ROTATING:
                    time += float(motion.get("spindle_start", 0.0))
                state["spindle"] = True
            elif name == "GCodeStopSpindle":
                state["spindle"] = False
            elif name == "GCodeDigitalOutputOn":
                state["outputs"].add(int(g.params["P"].value))
                if int(g.params["P"].value) == spray_out and layer is not None:
                    mix = {feeders[k]: v / scale for k, v in state["analog"].items() if k in feeders}
                    if not layer["sprays"] or layer["sprays"][-1] != mix:
                        layer["sprays"].append(mix)
            elif name == "GCodeDigitalOutputOff":
                state["outputs"].discard(int(g.params["P"].value))
            elif name in ("GCodeAnalogOutputImmediate", "GCodeAnalogOutputSyncronized", "GCodeAnalogOutputSynchronized"):
                params = {str(w.letter): float(w.value) for w in line.block.modal_params}
                if "E" not in params or "Q" not in params:
                    bad(n, "an analog output without E and Q")
                else:
                    state["analog"][int(params["E"])] = params["Q"]
            elif name in ("GCodePauseProgram",):
                pauses += 1
            elif word in ("M02", "M30") or name.startswith("GCodeEndProgram"):
                state["ended"] = True
                if not state["safe"]:
                    bad(n, "the program ends away from the safe height")
        # Motion after the modal words of the line (speed, feed) are set.
        for g in line.block.gcodes:
            name = type(g).__name__
            if name not in ("GCodeRapidMove", "GCodeLinearMove"):
                continue
            if not (state["mm"] and state["absolute"]):
                bad(n, "motion before G21 and G90")
            if machine:
                if name != "GCodeRapidMove" or set(g.params) != {"Z"} or float(g.params["Z"].value) != 0.0:
                    bad(n, "a move in machine coordinates other than the rapid to Z 0")
                if motion and state["pos"][2] is not None:
                    top = profile["travel"]["z"][1]
                    time += trapezoid(top - state["pos"][2], motion["rapid"][2] / 60.0, motion["acceleration"][2])
                state["pos"][2] = None
                state["safe"] = True
                continue
            target = list(state["pos"])
            for i, axis in enumerate("XYZ"):
                if axis in g.params:
                    target[i] = float(g.params[axis].value)
            if target == state["pos"]:
                noop += 1
            moved = [
                a in g.params and (state["pos"][i] is None or abs(target[i] - state["pos"][i]) > 1e-9)
                for i, a in enumerate("XYZ")
            ]
            if moved[2]:
                state["safe"] = False
            moves_xy = any(
                a in g.params and state["pos"][i] is not None and abs(target[i] - state["pos"][i]) > 1e-9
                for i, a in enumerate("XY")
            )
            tool = state["loaded"]
            kind = kinds.get(tool)
            # Time: a straight move from rest to rest within every axis' limits.
            if motion and all(p is not None for p in state["pos"]):
                d = [target[i] - state["pos"][i] for i in range(3)]
                length = math.sqrt(sum(x * x for x in d))
                if length > 0:
                    v = math.inf
                    a = math.inf
                    for i in range(3):
                        u = abs(d[i]) / length
                        if u > 1e-12:
                            v = min(v, motion["rapid"][i] / 60.0 / u)
                            a = min(a, motion["acceleration"][i] / u)
                    if name == "GCodeLinearMove":
                        v = min(v, (state["feed"] or math.inf) / 60.0)
                        chain.append((length, v, a, [x / length for x in d]))
                    else:
                        time += trapezoid(length, v, a)
            elif motion and state["pos"][2] is None and target[2] is not None and all(p is not None for p in state["pos"][:2]) and not moves_xy:
                # Down from the safe height.
                top = profile["travel"]["z"][1]
                time += trapezoid(top - target[2], motion["rapid"][2] / 60.0, motion["acceleration"][2])
            if layer is not None and target[2] is not None and kind and (name == "GCodeLinearMove" or kind == "laser"):
                if kind != "laser" or moved[2] or name == "GCodeLinearMove":
                    low = layer["lowest"].get(kind, math.inf)
                    layer["lowest"][kind] = min(low, target[2])
            if kind == "laser" and layer is not None and moved[2] and state["pos"][2] is not None:
                if target[2] > state["pos"][2]:
                    laser_rising = True
                elif laser_rising:
                    layer["laser_z_cycles"] += 1
                    laser_rising = False
            if name == "GCodeLinearMove":
                if not state["feed"]:
                    bad(n, "feed move without a feed rate")
                if state["offset"] != tool:
                    bad(n, f"feed move with the length offset of H{state['offset']}, tool {tool} loaded")
                if kind in ROTATING and moved[2] and not moves_xy and state["pos"][2] is not None and target[2] < state["pos"][2]:
                    plunges += 1
                if moves_xy:
                    if working(tool):
                        dd = math.hypot(target[0] - state["pos"][0], target[1] - state["pos"][1])
                        lengths[tool] = lengths.get(tool, 0.0) + dd
                        if kind in ROTATING and target[2] is not None:
                            state["top"] = max(state["top"], target[2])
                    else:
                        bad(n, f"feed move in XY with tool {tool} ({kind}) not working")
            else:
                if moves_xy and kind in ("spray", "dispenser", "laser") and working(tool):
                    bad(n, f"rapid move with the {kind} on")
                # A rapid move of a tool that touches the work, across or down, ends
                # above every surface worked so far.
                touches = kind in ROTATING or kind == "dispenser"
                if touches and target[2] is not None and target[2] < state["top"] - 1e-9:
                    bad(n, f"rapid move to Z{target[2]} below the surface at {state['top']}")
            state["pos"] = target
        if laser_rising and kinds.get(state["loaded"]) != "laser":
            laser_rising = False
    time += chain_time(chain, deviation)
    if not state["ended"]:
        bad(len(text), "the program does not end with M2 or M30")
    if state["spindle"] or state["outputs"]:
        bad(len(text), "the program ends with the spindle or an output on")
    report = {
        "lengths": {str(k): v for k, v in sorted(lengths.items())},
        "tool_changes": changes,
        "tool_changes_at_safe_height": changes_safe,
        "pauses": pauses,
        "noop_moves": noop,
        "plunges": plunges,
        "laser_z_cycles": sum(l["laser_z_cycles"] for l in layers),
        "time": time,
        "layers": layers,
        "lines": len(text),
        "violations": violations,
    }
    print(json.dumps(report))
    return 1 if violations else 0


if __name__ == "__main__":
    sys.exit(main())
