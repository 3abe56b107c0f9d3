#!/usr/bin/env python3
"""Independent G-code replay checker for Lamina's multi-material G-code.

The checker reads a G-code file the way a printer's firmware would and judges
what the printer would make of it. It is written from the firmware
documentation (Marlin's G-code reference and RepRapFirmware's G-code
dictionary), not from Lamina's exporter, so that it can catch the exporter's
mistakes instead of repeating them.

Checks (each reported with the line numbers of its violations):

1. parse      every line is understood; unknown commands are listed, not
              failed. Malformed words stop the run with exit status 2.
2. features   ``;TYPE:<NAME>`` comments tag the extrusion that follows (PART,
              SKIRT, PRIME, TOWER, PURGE); extrusion before any tag fails.
3. layers     ``;LAYER:<n>`` starts a layer whose print Z is the Z of its
              extrusion; layer Z never decreases, and all extrusion of a layer
              happens at that Z (z-hops between extrusions are fine).
4. heating    no filament movement (extrusion, retraction, G10/G11 firmware
              retraction) unless a tool is selected and its hotend's target is
              at least the cold-extrusion limit (Marlin's EXTRUDE_MINTEMP,
              170 degC by default, M302) and the firmware has waited for it
              since the target was last raised (M109 for that hotend, or
              M116). Marlin: M104/M109 [T<hotend>] S|R set targets, M109 waits
              (with S only when heating, which still leaves the hotend at or
              above target). RepRapFirmware: G10 P<tool> S<active> R<standby>
              and M568 P S R set tool temperatures; selecting a tool heats it
              to its active temperature and drops the previous tool to
              standby; M116 [P<tool>|H<heater>] waits.
5. bed        every move's end point (straight moves, so the end points of a
              convex bed are enough) lies inside ``--bed`` or ``--bed-circle``.
6. mixes      each mix (Marlin M163 S<ch> P<f> then M164 S<vtool>; Marlin
              M165 A B C D H I; RepRapFirmware M567 P<tool> E<a:b:...>) sums
              to 1 within 0.011.
7. volume     PART volume = filament actually pushed (E advance beyond the
              retracted position, so retractions and their recoveries cancel)
              times the filament cross-section; with ``--mesh`` it must be the
              mesh volume within ``--volume-tol``.
8. coverage   with ``--mesh``, every N-th layer: PART beads as flat-ended
              rectangles (width = E x filament area / (length x layer
              height)) must cover the mesh's cross-section at mid-layer
              (>= ``--coverage-min``) and not overlap beyond ``--overlap-max``
              (the overlap of consecutive segments of one continuous
              extrusion is not counted).
9. time       the moves are replayed with trapezoidal velocity profiles:
              acceleration from M204 (P printing, T travel, R retraction;
              Marlin semantics, S sets P and T) capped per axis by M201,
              speed capped per axis by M203 (mm/s in Marlin, mm/min in
              RepRapFirmware), junction speeds from Marlin's junction
              deviation (M205 J, 0.013 mm by default) or from jerk limits when
              the file sets them (M205 X Y Z E in mm/s, RepRapFirmware M566 in
              mm/min), with a look-ahead over the whole file (a backward then a
              forward pass). G4 dwells count; heating waits (M109, M190, M116)
              count as 0 s unless ``--heating-rate`` turns the heating model
              on (below); each change of tool adds ``--tool-change-time``
              (default 0). The result is compared with the file's footer
              ``; estimated printing time: <seconds> s`` within ``--time-tol``.

Heating model (``--heating-rate``; off by default). Every heater (each hotend
as check 4 keys them, and the bed) is at ``--ambient`` (25 degC) at time 0.
When its target changes -- M104/M109 S|R, M140/M190, RepRapFirmware G10 P S R
and M568, a tool selected (active) or deselected (standby) -- at machine time
t (the look-ahead's time of all moves before that line, plus the dwells and
waits before it), it moves linearly toward the target: up at
``--heating-rate`` (bed ``--bed-heating-rate``, 0.5), down at
``--cooling-rate`` (1.0; the bed at a fixed 0.3 degC/s), never below ambient.
A wait is a dwell at its line (the planner is empty there) lasting:

* Marlin M109 S<t> (hotend) / M190 S<t> (bed; the same with the bed's rate and
  ``--bed-residency``): 0 s when the heater is above the target (S does not
  wait for cooling); else, with a residency time R (``--residency``, Marlin's
  TEMP_RESIDENCY_TIME, 10 s by default), until it is within TEMP_WINDOW (1
  degC) of the target, then R; already within the window at the wait, 4R/3
  (wait_for_hotend/wait_for_bed then start the residency timer R/3 late,
  Marlin PR #18421). With R = 0 the firmware waits until the heater reaches
  the target itself. M109/M190 R<t> waits the same way for cooling too (to
  within the window above the target; a target below ambient ends the wait
  when the heater arrives at ambient, where Marlin's cooling-slope check would
  give up). M109/M190 with neither S nor R does not wait.
* RepRapFirmware M109/M190 (S heating only, R both ways; M109 with neither
  still waits for the tool): until within TEMPERATURE_CLOSE_ENOUGH (1 degC).
  M116 [P<tool>|H<heater>] (neither: every hotend and the bed): until every
  named heater is within S<tol> (2 degC) of its target, heating or cooling.
  Targets below 40 degC are not waited for; no residency (``--residency``
  defaults to 0 for RepRapFirmware).

A change of tool is a ``T<n>`` that selects another tool than the selected one
(not ``T-1``, not the same tool, not the first selection after none, and not on
a mixing head, whose tools are mixes of one nozzle); its dwell comes before
RepRapFirmware switches the heaters (standby after tfree, active after tpre).
With multiple motion systems both are timed per stream (the part before the
fork on stream 0's clock, then each stream's heaters on its own; see
README.md, "Multiple motion systems").

It also reports per-tool and per-mix-channel filament, tool changes, mix
changes, XY extents and layer count.

A file that selects motion systems (RepRapFirmware 3.5 ``M596``) is split into
one stream per motion system and replayed by ``multi_motion.py`` (same checks
per stream, plus barriers, build time, axis/tool ownership and collisions of
the tool heads); see README.md.

Run ``python3 gcode_replay.py --help`` for the command line; exit status is 0
when every check passes, 1 when one fails and 2 on a usage or parse error.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
from dataclasses import dataclass, field
from functools import reduce
from itertools import accumulate
from typing import Iterable, NamedTuple

import numpy as np

if __name__ == "__main__":
    # multi_motion imports this module by name: let it share this copy (and its
    # exception classes) when the checker runs as a script.
    sys.modules.setdefault("gcode_replay", sys.modules["__main__"])

# ---------------------------------------------------------------------------
# Defaults taken from the firmware documentation / stock configuration.
# ---------------------------------------------------------------------------

#: Marlin's stock cold-extrusion limit (EXTRUDE_MINTEMP, see M302).
DEFAULT_MIN_EXTRUDE_TEMP = 170.0
#: Marlin's stock junction deviation (JUNCTION_DEVIATION_MM).
DEFAULT_JUNCTION_DEVIATION = 0.013
#: Marlin's stock DEFAULT_ACCELERATION / TRAVEL / RETRACT accelerations (mm/s^2).
DEFAULT_ACCEL = 3000.0
#: Marlin's stock classic-jerk Z and E values (mm/s) used when only X/Y are set.
DEFAULT_Z_JERK = 0.3
DEFAULT_E_JERK = 5.0
#: Mix sums may be off by two-decimal rounding.
MIX_SUM_TOL = 0.011
#: Bed containment tolerance (mm).
BED_TOL = 1e-6
#: Extrusion counted at "the layer Z" within this tolerance (mm).
LAYER_Z_TOL = 1e-4
#: Violations kept per check in the report (the count is always exact).
MAX_EXAMPLES = 200

# Heating model (on with --heating-rate): what a wait for a temperature costs.
#: Hotend cooling and bed heating rates (degC/s) when the options leave them out.
DEFAULT_COOLING_RATE = 1.0
DEFAULT_BED_HEATING_RATE = 0.5
#: The bed cools at this fixed rate (degC/s): there is no option for it, and only
#: M190 R (or a target re-raised after lowering it) ever depends on it.
BED_COOLING_RATE = 0.3
DEFAULT_AMBIENT = 25.0
#: Marlin's stock TEMP_RESIDENCY_TIME and TEMP_BED_RESIDENCY_TIME (s).
MARLIN_RESIDENCY = 10.0
#: Marlin's TEMP_WINDOW / TEMP_BED_WINDOW (degC): the residency timer starts
#: when the heater is this close to its target.
MARLIN_TEMP_WINDOW = 1.0
#: Marlin's wait_for_hotend/wait_for_bed, finding the heater already inside the
#: window on its first pass, start the residency timer a third of the residency
#: time in the future (PR #18421, meant to give 4/3 of the residency). Current
#: Marlin tests that timer with the three-argument PENDING of core/millis_t.h,
#: ``(now - start) < interval`` in unsigned arithmetic: a start in the future
#: wraps, the test is false at once and the wait ends (older releases compared
#: signed and waited 4/3). The current code is modelled: such a wait takes no time.
MARLIN_FIRST_PASS_RESIDENCY = 0.0
#: RepRapFirmware's TEMPERATURE_CLOSE_ENOUGH (degC), the tolerance of M109/M190.
RRF_CLOSE_ENOUGH = 1.0
#: RepRapFirmware's default M116 tolerance (degC; M116 S overrides).
RRF_M116_TOLERANCE = 2.0
#: RepRapFirmware does not wait for targets below this (TEMPERATURE_LOW_SO_DONT_CARE, degC).
RRF_LOW_DONT_CARE = 40.0
#: Heater key of the bed in the heating model (hotends are keyed by number).
BED = "bed"

FEATURE_TYPES = ("PART", "SKIRT", "PRIME", "TOWER", "PURGE")
AXES = "XYZ"


class ParseError(Exception):
    """A line the checker cannot read; carries its line number."""

    def __init__(self, line: int, message: str):
        super().__init__(f"line {line}: {message}")
        self.line = line
        self.message = message


class UsageError(Exception):
    """A bad command-line argument or input file."""


# ---------------------------------------------------------------------------
# Line tokenisation
# ---------------------------------------------------------------------------

_CMD_RE = re.compile(r"^([GMT])(-?\d+)(?:\.(\d+))?$", re.IGNORECASE)
_WORD_RE = re.compile(r"([A-Za-z])([-+]?(?:\d+\.?\d*|\.\d+)(?::[-+]?(?:\d+\.?\d*|\.\d+))*)?")
_QUOTED_RE = re.compile(r'"[^"]*"')
_LINE_NO_RE = re.compile(r"^N\d+\s*", re.IGNORECASE)
_CHECKSUM_RE = re.compile(r"\*\d+\s*$")
_TIME_RE = re.compile(r"estimated printing time:\s*([-+]?\d+(?:\.\d*)?)\s*s", re.IGNORECASE)
_FLAVOR_RE = re.compile(r"^flavor:\s*([^\s,;]+)", re.IGNORECASE)
_LAYER_RE = re.compile(r"^LAYER:\s*([-+]?\d+)", re.IGNORECASE)
_TYPE_RE = re.compile(r"^TYPE:\s*(\S+)", re.IGNORECASE)


def _number(text: str, line: int, letter: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ParseError(line, f"bad value {letter}{text!r}") from None


#: Commands whose argument is free text (messages, file names).
_FREE_TEXT = {"M23", "M28", "M29", "M30", "M32", "M33", "M117", "M118", "M928"}
_META_WORDS = ("if", "elif", "else", "while", "break", "continue", "var", "global", "set", "echo", "abort")


def tokenize(code: str, line: int) -> tuple[str, dict[str, str | None]]:
    """Split a code part (no comment) into its command and raw parameter words.

    Returns ``("G1", {"X": "10", "E": "0.5"})``; a letter without a value maps to
    None (``G28 X``). Glued words (``G1X10Y5``) are accepted; line numbers
    (``N12``) and checksums (``*71``) are dropped, and so are quoted strings
    (RepRapFirmware names). RepRapFirmware meta commands come back as
    ``("meta:<keyword>", {})``. A malformed word raises ParseError.
    """
    code = _LINE_NO_RE.sub("", code)
    code = _CHECKSUM_RE.sub("", code).strip()
    if '"' in code:
        code = _QUOTED_RE.sub("", code)
    tokens = code.split()
    if not tokens:
        raise ParseError(line, "empty command")
    first = tokens[0].lower()
    if first in _META_WORDS:
        return "meta:" + first, {}
    m = _CMD_RE.match(tokens[0])
    if m and tokens[0].upper() in _FREE_TEXT:
        return tokens[0].upper(), {}
    if m:
        params: dict[str, str | None] = {}
        for w in tokens[1:]:
            letter = w[0].upper()
            value = w[1:]
            if not letter.isalpha() or (value and not (value[0].isdigit() or value[0] in "+-.")):
                raise ParseError(line, f"bad word {w!r} in {code!r}")
            params[letter] = value if value else None
        cmd = m.group(1).upper() + str(int(m.group(2))) + (f".{m.group(3)}" if m.group(3) else "")
        return cmd, params
    # Glued words: G1X10Y5E0.2
    stripped = "".join(tokens)
    pos = 0
    found = []
    while pos < len(stripped):
        w = _WORD_RE.match(stripped, pos)
        if not w or w.group(2) is None:
            raise ParseError(line, f"cannot read {code!r}")
        found.append((w.group(1).upper(), w.group(2)))
        pos = w.end()
    letter, num = found[0]
    if letter not in "GMT" or ":" in num:
        raise ParseError(line, f"no G, M or T command in {code!r}")
    if "." in num:
        major, minor = num.split(".", 1)
        cmd = f"{letter}{int(float(major))}.{minor}"
    else:
        cmd = f"{letter}{int(num)}"
    return cmd, {k: v for k, v in found[1:]}


#: Kinds of statement ``statements`` yields.
COMMENT = "comment"
MOVE = "move"
MOVE_WORDS = "move words"
COMMAND = "command"


def statements(text: str) -> Iterable[tuple[int, str, str | None, object]]:
    """The lines of ``text`` that say something, as ``(line, kind, command,
    params)``: a comment-only line is ``(line, COMMENT, None, "<comment text>")``
    (the text after ``;``, stripped); a plain ``G0``/``G1`` (space after the
    command, letters and numbers only) is ``(line, MOVE, "G0"|"G1", {letter:
    float | None})`` without the tokenizer (the fast path); a ``G0``/``G1`` of
    that form whose words are not plain numbers is ``(line, MOVE_WORDS, cmd,
    raw words)``; every other command ``(line, COMMAND, cmd, raw words)`` as
    ``tokenize`` returns them. Comments after code are dropped; blank lines are
    skipped. A malformed word raises ParseError.
    """
    for lineno, raw in enumerate(text.splitlines(), 1):
        c = raw.find(";")
        if c >= 0:
            code = raw[:c].strip()
            if not code:
                yield lineno, COMMENT, None, raw[c + 1:].strip()
                continue
        else:
            code = raw.strip()
            if not code:
                continue
        # Fast path for plain moves.
        if (code[0] == "G" or code[0] == "g") and len(code) > 2 and code[1] in "01" and code[2] == " ":
            params = {}
            try:
                for w in code[3:].split():
                    if not w[0].isalpha():
                        raise ValueError(w)
                    params[w[0].upper()] = float(w[1:]) if len(w) > 1 else None
            except ValueError:
                cmd, raw_params = tokenize(code, lineno)
                yield lineno, MOVE_WORDS, cmd, raw_params
                continue
            yield lineno, MOVE, "G" + code[1], params
            continue
        cmd, raw_params = tokenize(code, lineno)
        yield lineno, COMMAND, cmd, raw_params


# ---------------------------------------------------------------------------
# Machine state
# ---------------------------------------------------------------------------


@dataclass
class Heater:
    """One heater: its target and whether the firmware has waited for it since
    the target was last raised."""

    target: float = 0.0
    waited: bool = False

    def set_target(self, value: float) -> None:
        if value > self.target + 1e-9:
            self.waited = False
        self.target = value


@dataclass
class Tool:
    """A tool (physical extruder, RepRapFirmware tool or Marlin virtual tool)."""

    number: int
    active: float | None = None  # RepRapFirmware active temperature
    standby: float | None = None  # RepRapFirmware standby temperature
    ever_selected: bool = False
    # RepRapFirmware M568 A: the heater state set without selecting the tool
    # (0 off, 1 standby, 2 active); selecting or deselecting the tool sets it again.
    state: int | None = None
    drives: list[int] | None = None  # M563 D
    heaters: list[int] | None = None  # M563 H
    mix: list[float] | None = None  # normalised mix (Marlin vtool / RRF M567)


class WaitRule(NamedTuple):
    """When a firmware's wait for one heater ends (see ``Ramp.wait``)."""

    cooling: bool  # waits for the heater to cool down too (M109/M190 R, M116)
    window: float  # done within this of the target (degC)
    residency: float  # then holds this long (s)
    first_pass: float  # the whole wait when already within the window (s)
    low: float  # targets below this are not waited for (degC)


class Ramp:
    """A heater's temperature over machine time: from (t0, temp0) it moves
    linearly toward its target, up at ``up`` and down at ``down`` degC/s, and
    stays there; it never cools below the ambient ``floor``."""

    __slots__ = ("t0", "temp0", "target", "up", "down", "floor")

    def __init__(self, up: float, down: float, floor: float):
        self.t0 = 0.0
        self.temp0 = floor
        self.target = 0.0
        self.up = up
        self.down = down
        self.floor = floor

    def at(self, t: float) -> float:
        goal = max(self.target, self.floor)
        dt = t - self.t0
        if goal >= self.temp0:
            return min(goal, self.temp0 + self.up * dt)
        return max(goal, self.temp0 - self.down * dt)

    def retarget(self, t: float, target: float) -> None:
        self.temp0 = self.at(t)
        self.t0 = t
        self.target = target

    def wait(self, t: float, rule: WaitRule) -> float:
        """Seconds a wait starting at t takes for this heater."""
        temp = self.at(t)
        target = self.target
        if target < rule.low:
            return 0.0
        if temp > target and not rule.cooling:
            return 0.0  # Marlin M109/M190 S, RRF M109/M190 S: no wait for cooling
        if abs(temp - target) <= rule.window:
            return rule.first_pass
        if temp < target:
            return (target - rule.window - temp) / self.up + rule.residency
        level = target + rule.window
        if level < self.floor:
            # It stops at ambient, never reaching the window: Marlin gives up when
            # the temperature stops falling (MIN_COOLING_SLOPE), here when it arrives.
            return (temp - self.floor) / self.down
        return (temp - level) / self.down + rule.residency

    def copy(self) -> "Ramp":
        r = Ramp(self.up, self.down, self.floor)
        r.t0, r.temp0, r.target = self.t0, self.temp0, self.target
        return r


class HeatingModel:
    """The machine's heaters on one clock (``Ramp`` each, created at ambient on
    first use): ``apply`` plays a ``Replay.heat_events`` entry at machine time
    t. Shared by the single-stream replay (``heating_waits``) and the
    multi-motion one, which copies the model for each stream at the fork."""

    def __init__(self, o: "Options"):
        self.o = o
        self.ramps: dict[int | str, Ramp] = {}

    def ramp(self, key: int | str) -> Ramp:
        h = self.ramps.get(key)
        if h is None:
            o = self.o
            if key == BED:
                h = Ramp(o.bed_heating_rate, BED_COOLING_RATE, o.ambient)
            else:
                h = Ramp(o.heating_rate, o.cooling_rate, o.ambient)
            self.ramps[key] = h
        return h

    def apply(self, t: float, ev: tuple) -> float:
        """A target change (``("set", ...)``: 0 s) or a wait (its seconds:
        until every heater it names is done by its rule) at time t."""
        if ev[0] == "set":
            self.ramp(ev[3]).retarget(t, ev[4])
            return 0.0
        return max((self.ramp(k).wait(t, ev[5]) for k in ev[4]), default=0.0)

    def copy(self) -> "HeatingModel":
        m = HeatingModel(self.o)
        m.ramps = {k: r.copy() for k, r in self.ramps.items()}
        return m


# A move for the time replay is a plain tuple (fast to build by the million):
#   (length, speed, accel, ux, uy, uz, ue, cx, cy, cz, ce, stop_before)
# length: path length (XYZ, or |E| for E-only moves), mm; speed: nominal
# speed, mm/s; accel: mm/s^2; u: junction direction (XYZ unit vector, or
# (0, 0, 0, +-1) for E-only moves); c: per-axis displacement per unit of path
# (for jerk limits and axis caps); stop_before: the planner is empty before it.
M_LEN, M_SPEED, M_ACCEL = 0, 1, 2
M_U = slice(3, 7)
M_C = slice(7, 11)
M_STOP = 11


def make_move(dx: float, dy: float, dz: float, de: float, speed: float, accel: float,
              stop_before: bool = False) -> tuple | None:
    """A move tuple from a displacement (mm), nominal speed (mm/s) and
    acceleration (mm/s^2); None when nothing moves."""
    lxyz = math.sqrt(dx * dx + dy * dy + dz * dz)
    if lxyz > 1e-9:
        return (lxyz, speed, accel, dx / lxyz, dy / lxyz, dz / lxyz, 0.0,
                dx / lxyz, dy / lxyz, dz / lxyz, de / lxyz, stop_before)
    if abs(de) > 1e-9:
        s = 1.0 if de > 0 else -1.0
        return (abs(de), speed, accel, 0.0, 0.0, 0.0, s, 0.0, 0.0, 0.0, s, stop_before)
    return None


class Check:
    """Collects the violations of one check."""

    def __init__(self, name: str, description: str):
        self.name = name
        self.description = description
        self.count = 0
        self.examples: list[dict] = []
        self.status = "pass"
        self.details: dict = {}

    def fail(self, line: int | None, message: str) -> None:
        self.count += 1
        self.status = "fail"
        if len(self.examples) < MAX_EXAMPLES:
            self.examples.append({"line": line, "message": message})

    def skip(self, why: str) -> None:
        if self.count == 0:
            self.status = "skipped"
        self.details["skipped"] = why

    def to_json(self) -> dict:
        out = {
            "status": self.status,
            "description": self.description,
            "violations": self.count,
            "examples": self.examples,
        }
        out.update(self.details)
        return out


@dataclass
class Options:
    """Everything the command line sets."""

    mesh: str | None = None
    place: str = "centre"
    bed_rect: tuple[float, float, float, float] | None = None
    bed_circle: tuple[float, float, float] | None = None
    filament: float = 1.75
    min_extrude_temp: float = DEFAULT_MIN_EXTRUDE_TEMP
    volume_tol: float = 0.02
    coverage_min: float = 0.99
    overlap_max: float = 0.05
    coverage_every: int = 5
    bead_ends: str = "flat"  # "flat" rectangles (the contract) or "round"
    time_tol: float | None = None  # None: 0.05, or 0.02 with multiple motion systems
    flavor: str | None = None  # None: from the header, else marlin
    accel: tuple[float, float, float] = (DEFAULT_ACCEL, DEFAULT_ACCEL, DEFAULT_ACCEL)
    junction_deviation: float = DEFAULT_JUNCTION_DEVIATION
    # Multiple motion systems (multi_motion.py); the file's header fills what is None/empty.
    head_radius: float | None = None  # envelope radius of every head (mm)
    envelopes: dict[int, float] = field(default_factory=dict)  # system -> envelope radius (mm)
    axis_maps: dict[int, dict[str, str]] = field(default_factory=dict)  # system -> {"X": "U", ...}
    homes: dict[int, tuple[float, float]] = field(default_factory=dict)  # system -> head X, Y after homing
    shared_gantry: bool | None = None  # heads on one gantry: check X order instead of discs
    dual_gantry: bool | None = None  # heads on two gantries over one pair of Y rails: check Y order
    # system -> (feed scale, acceleration scale): a machine that runs one system's
    # moves slower than the file asks, to check what the file's synchronisation holds.
    perturb: dict[int, tuple[float, float]] = field(default_factory=dict)
    extrusion_tol: float = 0.01  # planned extrusion per tool
    # Heating waits and tool changes in the time replay; the heating model is on
    # only with a heating rate (None: waits take 0 s, as the replay always did).
    heating_rate: float | None = None  # hotends heating, degC/s
    cooling_rate: float = DEFAULT_COOLING_RATE  # hotends cooling, degC/s
    bed_heating_rate: float = DEFAULT_BED_HEATING_RATE  # degC/s
    residency: float | None = None  # s; None: 10 (Marlin) or 0 (RepRapFirmware)
    bed_residency: float | None = None  # s; the same defaults
    ambient: float = DEFAULT_AMBIENT  # degC: every heater at time 0, and the floor of cooling
    tool_change_time: float = 0.0  # s of dwell per change of tool


#: Time tolerance when --time-tol is not given: one motion system / several.
DEFAULT_TIME_TOL = 0.05
DEFAULT_TIME_TOL_MULTI = 0.02


def time_tolerance(o: "Options", multi: bool = False) -> float:
    if o.time_tol is not None:
        return o.time_tol
    return DEFAULT_TIME_TOL_MULTI if multi else DEFAULT_TIME_TOL


@dataclass
class Layer:
    ordinal: int
    number: int
    line: int
    z: float | None = None
    height: float | None = None
    sampled: bool = False
    # PART segments: x0, y0, x1, y1, deposited filament length (mm), run id
    segs: list[tuple[float, float, float, float, float, int]] = field(default_factory=list)
    part_volume: float = 0.0


# ---------------------------------------------------------------------------
# The replay
# ---------------------------------------------------------------------------


class Replay:
    """Executes a G-code file line by line against a model of the firmware."""

    def __init__(self, opts: Options):
        self.o = opts
        self.area = math.pi * (opts.filament / 2.0) ** 2
        self.flavor = opts.flavor or "marlin"
        self.flavor_from = "option" if opts.flavor else "default"
        self.mixing = False
        self.uses_t = False
        self.line = 0

        self.checks = {
            "parse": Check("parse", "every line is read; unknown commands are listed"),
            "features": Check("features", "extrusion is preceded by a ;TYPE: marker"),
            "layers": Check("layers", "layer Z never decreases; extrusion happens at the layer Z"),
            "heating": Check("heating", "filament moves only with a selected, hot, waited-for tool"),
            "bed": Check("bed", "every move stays inside the bed"),
            "mixes": Check("mixes", "every mix sums to 1 within 0.011"),
            "volume": Check("volume", "PART volume matches the mesh volume"),
            "coverage": Check("coverage", "PART beads cover each sampled layer's cross-section without overlap"),
            "time": Check("time", "replayed time matches the file's estimate"),
        }
        # Positioning
        self.pos = [None, None, None]  # logical X Y Z (None: unknown)
        self.offset = [0.0, 0.0, 0.0]  # machine = logical + offset
        self.e = 0.0
        self.abs_xyz = True
        self.m83 = False
        self.units = 1.0  # G20 -> 25.4
        self.feed = None  # mm/min, modal
        self.speed_factor = 1.0  # M220
        self.flow_factor = 1.0  # M221
        self.volumetric = False  # M200 D>0
        # Tools / heaters
        self.tools: dict[int, Tool] = {}
        self.current: int | None = None
        self.heaters: dict[int, Heater] = {}
        self.ready_cache: tuple[int, list[str]] | None = None
        self.bed_target = 0.0
        self.retracted: dict[int, float] = {}  # per nozzle (heater key)
        self.fw_retracted: dict[int, bool] = {}
        self.tool_changes = 0
        self.tool_change_s = 0.0  # dwell of tool changes (also in self.dwell)
        self.tool_selects: list[dict] = []
        # Heating model: target changes and waits, each stamped with the number
        # of moves and the dwell before it; timed once the look-ahead has timed
        # the moves (heating_waits).
        self.heat_on = opts.heating_rate is not None
        self.heat_events: list[tuple] = []
        # Mixing
        self.collector: dict[int, float] = {}
        self.mix_commands = 0
        self.mix_changes = 0
        self.mix_channels = 0
        # Features and layers
        self.feature: str | None = None
        self.layers: list[Layer] = []
        self.layer: Layer | None = None
        self.run_id = 0
        self.in_run = False
        self.last_part_end: tuple[float, float] | None = None
        # Accounting
        self.volume_by_type: dict[str, float] = {}
        self.filament_by_tool: dict[int, float] = {}
        self.filament_by_channel: dict[int, float] = {}
        self.unknown: dict[str, int] = {}
        self.warnings: list[str] = []
        self.extents = {"moves": [math.inf, math.inf, -math.inf, -math.inf],
                        "extrusion": [math.inf, math.inf, -math.inf, -math.inf]}
        self.estimated_time: float | None = None
        self.estimated_time_line: int | None = None
        # Kinematics
        self.accel_print, self.accel_travel, self.accel_retract = opts.accel
        self.max_accel = [math.inf] * 4  # X Y Z E (mm/s^2)
        self.max_speed = [math.inf] * 4  # X Y Z E (mm/s)
        self.jd = opts.junction_deviation
        self.jerk: list[float] | None = None  # X Y Z E (mm/s) when classic jerk
        self.limited = False  # any M201/M203 limit set
        self.warned_feed = False
        self.moves: list[tuple] = []
        self.stop_pending = True
        self.dwell = 0.0
        self.arcs = 0
        self.fw_retract_count = 0

    # -- helpers -----------------------------------------------------------

    def tool(self, n: int) -> Tool:
        t = self.tools.get(n)
        if t is None:
            t = self.tools[n] = Tool(n)
        return t

    def heater(self, key: int) -> Heater:
        h = self.heaters.get(key)
        if h is None:
            h = self.heaters[key] = Heater()
        return h

    def set_target(self, key: int | str, value: float) -> None:
        """Sets a heater's target (hotend ``key``, or ``BED``) and stamps the
        change for the heating model."""
        if key == BED:
            self.bed_target = value
        else:
            self.heater(key).set_target(value)
        if self.heat_on:
            self.heat_events.append(("set", len(self.moves), self.dwell, key, value))

    def heat_wait(self, keys: Iterable[int | str], rule: WaitRule) -> None:
        """A wait for these heaters at this point (the planner is empty here),
        timed by the heating model."""
        if self.heat_on:
            self.heat_events.append(("wait", len(self.moves), self.dwell, self.line, list(keys), rule))

    def wait_rule(self, bed: bool, cooling: bool) -> WaitRule:
        """How M109 (``bed`` False) or M190 waits in this file's firmware.

        Marlin (wait_for_hotend / wait_for_bed): with a residency time the
        timer starts within TEMP_WINDOW of the target and the wait ends the
        residency later; already inside the window on the first pass, the
        timer starts a third of the residency late. Without residency the
        loop runs while the heater is heating (or cooling): until it reaches
        the target itself. RepRapFirmware: within TEMPERATURE_CLOSE_ENOUGH,
        no residency (unless the option gives one), nothing below 40 degC."""
        o = self.o
        rrf = self.flavor == "rrf"
        res = o.bed_residency if bed else o.residency
        if res is None:
            res = 0.0 if rrf else MARLIN_RESIDENCY
        if rrf:
            return WaitRule(cooling, RRF_CLOSE_ENOUGH, res, 0.0, RRF_LOW_DONT_CARE)
        if res > 0:
            return WaitRule(cooling, MARLIN_TEMP_WINDOW, res, res * MARLIN_FIRST_PASS_RESIDENCY, -math.inf)
        return WaitRule(cooling, 0.0, 0.0, 0.0, -math.inf)

    def tool_heaters(self, n: int) -> list[int]:
        """Heater keys of tool n: Marlin hotend n (hotend 0 for a mixing
        extruder's virtual tools); RepRapFirmware the M563 H list (else one
        heater of its own, keyed n)."""
        if self.flavor == "rrf":
            t = self.tools.get(n)
            if t is not None and t.heaters:
                return list(t.heaters)
            return [n]
        return [0] if self.mixing else [n]

    def active_tool(self) -> int | None:
        if self.current is not None:
            return self.current
        if not self.uses_t:
            return 0  # single-tool file: the one hotend is implicitly selected
        return None

    # -- pre-scan ----------------------------------------------------------

    def prescan(self, text: str) -> None:
        """Decides things the firmware knows from its configuration: the
        flavour (header hint), whether the head is a mixing one, and whether
        the file selects tools at all."""
        head = text[:20000]
        if self.o.flavor is None:
            for raw in head.splitlines():
                s = raw.strip()
                if s.startswith(";"):
                    m = _FLAVOR_RE.match(s[1:].strip())
                    if m:
                        v = m.group(1).lower()
                        self.flavor = "rrf" if any(k in v for k in ("rrf", "reprap", "duet")) else "marlin"
                        self.flavor_from = f"header ({m.group(1)})"
                        if "mix" in v:
                            self.mixing = True
                        break
        if re.search(r"^\s*M16[345]\b", text, re.MULTILINE | re.IGNORECASE):
            self.mixing = True
        if re.search(r"^\s*M567\b", text, re.MULTILINE | re.IGNORECASE):
            self.mixing = True
        if re.search(r"^\s*T\d+", text, re.MULTILINE | re.IGNORECASE):
            self.uses_t = True

    # -- main loop ---------------------------------------------------------

    def run(self, text: str) -> None:
        self.prescan(text)
        move = self.do_move
        for lineno, kind, cmd, params in statements(text):
            self.line = lineno
            if kind is MOVE:
                move(cmd, params)
            elif kind is COMMAND:
                self.command(cmd, params)
            elif kind is COMMENT:
                self.comment(params)
            else:
                move(cmd, self.floats(params))
        self.finish()

    def floats(self, raw: dict[str, str | None]) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for k, v in raw.items():
            if v is None:
                out[k] = None
            elif ":" in v:
                raise ParseError(self.line, f"unexpected list value {k}{v}")
            else:
                out[k] = _number(v, self.line, k)
        return out

    # -- comments ----------------------------------------------------------

    def comment(self, text: str) -> None:
        if not text:
            return
        c0 = text[0].upper()
        if c0 == "T":
            m = _TYPE_RE.match(text)
            if m:
                self.feature = m.group(1).upper()
                return
        elif c0 == "L":
            m = _LAYER_RE.match(text)
            if m:
                self.start_layer(int(m.group(1)))
                return
        if "estimated printing time" in text.lower():
            m = _TIME_RE.search(text)
            if m:
                self.estimated_time = float(m.group(1))
                self.estimated_time_line = self.line

    def start_layer(self, number: int) -> None:
        self.close_layer()
        ordinal = len(self.layers)
        every = max(1, self.o.coverage_every)
        lay = Layer(ordinal=ordinal, number=number, line=self.line,
                    sampled=(self.o.mesh is not None and ordinal % every == 0))
        self.layers.append(lay)
        self.layer = lay
        self.in_run = False

    def close_layer(self) -> None:
        self.in_run = False

    def finish(self) -> None:
        self.close_layer()

    # -- commands ----------------------------------------------------------

    def command(self, cmd: str, raw: dict[str, str | None]) -> None:
        handler = _HANDLERS.get(cmd)
        if handler is not None:
            handler(self, raw)
            return
        if cmd[0] == "T":
            self.select_tool(int(cmd[1:]))
            return
        self.unknown[cmd] = self.unknown.get(cmd, 0) + 1

    def sync(self) -> None:
        """The planner empties here (dwell, wait, tool change, homing)."""
        self.stop_pending = True

    # positioning ------------------------------------------------------------

    def e_relative(self) -> bool:
        if self.flavor == "rrf":
            return self.m83
        return self.m83 or not self.abs_xyz

    def do_move(self, cmd: str, p: dict[str, float | None], arc: bool = False) -> None:
        line = self.line
        f = p.get("F")
        if f is not None:
            self.feed = f * self.units
        units = self.units
        old = self.pos
        new = list(old)
        for i, a in enumerate(AXES):
            v = p.get(a)
            if v is None:
                continue
            v *= units
            if self.abs_xyz:
                new[i] = v
            elif old[i] is not None:
                new[i] = old[i] + v
        de = 0.0
        ev = p.get("E")
        if ev is not None:
            ev *= units
            if self.e_relative():
                de = ev
                self.e += ev
            else:
                de = ev - self.e
                self.e = ev
        self.pos = new
        # Machine-space displacement where both ends are known.
        d = [0.0, 0.0, 0.0]
        for i in range(3):
            if old[i] is not None and new[i] is not None:
                d[i] = new[i] - old[i]
        xy_known = new[0] is not None and new[1] is not None
        if xy_known:
            mx = new[0] + self.offset[0]
            my = new[1] + self.offset[1]
            self.check_bed(mx, my)
            ext = self.extents["moves"]
            if mx < ext[0]: ext[0] = mx
            if my < ext[1]: ext[1] = my
            if mx > ext[2]: ext[2] = mx
            if my > ext[3]: ext[3] = my
        de *= self.flow_factor
        deposit = 0.0
        if de != 0.0:
            deposit = self.filament_move(de, line)
        self.record_motion(d[0], d[1], d[2], de)
        # An arc's deposit counts toward the volumes but not as a bead.
        xy_len = 0.0 if arc else math.hypot(d[0], d[1])
        if deposit > 0.0:
            self.account_deposit(deposit, line, old, new, xy_len)
        else:
            self.in_run = False

    def readiness(self) -> tuple[int, list[str]]:
        """(nozzle key, problems) of the active tool, cached until a tool,
        temperature or wait command changes it."""
        if self.ready_cache is None:
            tool = self.active_tool()
            if tool is None:
                self.ready_cache = (0, ["{what} with no tool selected"])
            else:
                self.ready_cache = (self.tool_heaters(tool)[0], self.hot_problems(tool))
        return self.ready_cache

    def filament_move(self, de: float, line: int) -> float:
        """Checks a filament movement and returns the filament pushed beyond
        the retracted position (0 for retractions and recoveries)."""
        nozzle, problems = self.ready_cache if self.ready_cache is not None else self.readiness()
        if problems:
            what = "extrusion" if de > 0 else "retraction"
            for msg in problems:
                self.checks["heating"].fail(line, msg.format(what=what))
        r = self.retracted.get(nozzle, 0.0)
        if de < 0:
            self.retracted[nozzle] = r - de
            return 0.0
        pushed = de - r
        self.retracted[nozzle] = max(0.0, r - de)
        return pushed if pushed > 1e-12 else 0.0

    def hot_problems(self, tool: int) -> list[str]:
        """Why tool's hotend may not move filament (empty when it may); each
        message has a ``{what}`` placeholder."""
        out = []
        for key in self.tool_heaters(tool):
            h = self.heater(key)
            if h.target < self.o.min_extrude_temp:
                out.append(f"{{what}} with T{tool} whose hotend target is {h.target:g} degC "
                           f"(< {self.o.min_extrude_temp:g} degC): cold extrusion")
            elif not h.waited:
                out.append(f"{{what}} with T{tool} before waiting for its hotend (target {h.target:g} degC "
                           f"raised without M109/M116 since)")
        return out

    def check_hot(self, tool: int | None, line: int, what: str) -> None:
        if tool is None:
            self.checks["heating"].fail(line, f"{what} with no tool selected")
            return
        for msg in self.hot_problems(tool):
            self.checks["heating"].fail(line, msg.format(what=what))

    def account_deposit(self, deposit: float, line: int, old, new, xy_len: float) -> None:
        vol = deposit * self.area if not self.volumetric else deposit
        feature = self.feature
        if feature is None:
            self.checks["features"].fail(line, "extrusion before any ;TYPE: marker")
            feature = "(none)"
        self.volume_by_type[feature] = self.volume_by_type.get(feature, 0.0) + vol
        length = vol / self.area
        tool = self.active_tool()
        tkey = -1 if tool is None else tool
        self.filament_by_tool[tkey] = self.filament_by_tool.get(tkey, 0.0) + length
        mix = self.current_mix(tool)
        if mix is not None:
            for ch, frac in enumerate(mix):
                if frac:
                    self.filament_by_channel[ch] = self.filament_by_channel.get(ch, 0.0) + length * frac
        if xy_len <= 0.0 or old[0] is None or old[1] is None:
            self.in_run = False
            if feature == "PART" and self.layer is not None:
                self.layer.part_volume += vol
            elif feature == "PART":
                self.checks["layers"].fail(line, "PART extrusion before any ;LAYER: marker")
            return
        ox = old[0] + self.offset[0]
        oy = old[1] + self.offset[1]
        nx = new[0] + self.offset[0]
        ny = new[1] + self.offset[1]
        ext = self.extents["extrusion"]
        for x, y in ((ox, oy), (nx, ny)):
            if x < ext[0]: ext[0] = x
            if y < ext[1]: ext[1] = y
            if x > ext[2]: ext[2] = x
            if y > ext[3]: ext[3] = y
        lay = self.layer
        z = new[2] + self.offset[2] if new[2] is not None else None
        if lay is not None and z is not None:
            if lay.z is None:
                lay.z = z
            elif abs(z - lay.z) > LAYER_Z_TOL:
                self.checks["layers"].fail(
                    line, f"extrusion at Z {z:.4f} in layer {lay.number} printed at Z {lay.z:.4f}")
        if feature != "PART":
            self.in_run = False
            return
        if lay is None:
            self.checks["layers"].fail(line, "PART extrusion before any ;LAYER: marker")
            self.in_run = False
            return
        lay.part_volume += vol
        if lay.sampled:
            if not (self.in_run and self.last_part_end == (ox, oy)):
                self.run_id += 1
            lay.segs.append((ox, oy, nx, ny, length, self.run_id))
            self.in_run = True
            self.last_part_end = (nx, ny)

    def current_mix(self, tool: int | None) -> list[float] | None:
        if tool is None:
            return None
        if not self.mixing:
            return None
        t = self.tools.get(tool)
        if t is not None and t.mix is not None:
            return t.mix
        # Firmware default: virtual tool n / RRF tool drives = 100 % of channel n.
        if self.flavor == "rrf" and t is not None and t.drives:
            mix = [0.0] * (max(t.drives) + 1)
            mix[t.drives[0]] = 1.0
            return mix
        mix = [0.0] * (tool + 1)
        mix[tool] = 1.0
        return mix

    def check_bed(self, x: float, y: float) -> None:
        o = self.o
        if o.bed_rect is not None:
            x0, y0, x1, y1 = o.bed_rect
            if x < x0 - BED_TOL or x > x1 + BED_TOL or y < y0 - BED_TOL or y > y1 + BED_TOL:
                self.checks["bed"].fail(self.line, f"move to ({x:.4f}, {y:.4f}) outside the bed {x0:g},{y0:g},{x1:g},{y1:g}")
        elif o.bed_circle is not None:
            cx, cy, r = o.bed_circle
            if math.hypot(x - cx, y - cy) > r + BED_TOL:
                self.checks["bed"].fail(self.line, f"move to ({x:.4f}, {y:.4f}) outside the bed circle of radius {r:g} at ({cx:g}, {cy:g})")

    def record_motion(self, dx: float, dy: float, dz: float, de: float) -> None:
        """Queues a move for the time replay."""
        lxyz = math.sqrt(dx * dx + dy * dy + dz * dz)
        if lxyz > 1e-9:
            length = lxyz
            inv = 1.0 / lxyz
            cx, cy, cz, ce = dx * inv, dy * inv, dz * inv, de * inv
            ux, uy, uz, ue = cx, cy, cz, 0.0
            accel = self.accel_print if de != 0.0 else self.accel_travel
        elif de > 1e-9 or de < -1e-9:
            length = abs(de)
            ue = ce = 1.0 if de > 0 else -1.0
            ux = uy = uz = cx = cy = cz = 0.0
            # Marlin: E-only moves use the retract acceleration (M204 R);
            # RepRapFirmware's M204 has no R: they are printing moves.
            accel = self.accel_retract if self.flavor != "rrf" else self.accel_print
        else:
            return
        feed = self.feed
        if feed is None or feed <= 0:
            if not self.warned_feed:
                self.warnings.append(f"line {self.line}: move without a feed rate; timed at the axis limits")
                self.warned_feed = True
            speed = math.inf
        else:
            speed = feed * self.speed_factor / 60.0
        if self.limited:
            for lim_v, lim_a, c in zip(self.max_speed, self.max_accel, (cx, cy, cz, ce)):
                c = abs(c)
                if c > 1e-12:
                    if lim_v * 1.0 < speed * c:
                        speed = lim_v / c
                    if lim_a < accel * c:
                        accel = lim_a / c
        if speed == math.inf:
            speed = 1e6
        self.moves.append((length, speed, accel, ux, uy, uz, ue, cx, cy, cz, ce, self.stop_pending))
        self.stop_pending = False

    # tool and temperature -----------------------------------------------------

    def select_tool(self, n: int) -> None:
        self.ready_cache = None
        self.sync()
        line = self.line
        if n < 0:  # RepRapFirmware T-1: deselect
            if self.current is not None and self.flavor == "rrf":
                self.tool(self.current).state = None
                self.to_standby(self.current)
            self.current = None
            return
        prev = self.current
        t = self.tool(n)
        changed = prev is not None and prev != n
        if changed:
            self.tool_changes += 1
        self.tool_selects.append({"line": line, "tool": n})
        if changed and not self.mixing and self.o.tool_change_time > 0:
            # The firmware's own parking and pick-up, as a dwell. It comes before
            # the heaters' switch-over: RepRapFirmware sets the old tool to standby
            # after tfree and the new one active after tpre. A mixing head's tools
            # are mixes of one nozzle: selecting another moves no tool.
            self.dwell += self.o.tool_change_time
            self.tool_change_s += self.o.tool_change_time
        if self.flavor == "rrf" and prev != n:
            if prev is not None:
                self.tool(prev).state = None
                self.to_standby(prev)
            t.state = None
            if t.active is not None:
                for key in self.tool_heaters(n):
                    self.set_target(key, t.active)
        t.ever_selected = True
        self.current = n
        self.in_run = False

    def to_standby(self, n: int) -> None:
        self.ready_cache = None
        t = self.tool(n)
        if t.standby is not None:
            for key in self.tool_heaters(n):
                self.set_target(key, t.standby)

    def set_tool_temps(self, n: int, active: float | None, standby: float | None) -> None:
        """RepRapFirmware G10 P / M568: active and standby temperatures."""
        self.ready_cache = None
        t = self.tool(n)
        if active is not None:
            t.active = active
        if standby is not None:
            t.standby = standby
        if t.state is not None:
            self.apply_tool_state(n)
        elif self.current == n:
            if t.active is not None:
                for key in self.tool_heaters(n):
                    self.set_target(key, t.active)
        elif t.ever_selected and t.standby is not None:
            for key in self.tool_heaters(n):
                self.set_target(key, t.standby)

    def set_tool_state(self, n: int, state: int) -> None:
        """RepRapFirmware M568 A<state>: the tool's heaters off (0), at standby
        (1) or active (2), whether or not the tool is selected."""
        self.ready_cache = None
        self.tool(n).state = state
        self.apply_tool_state(n)

    def apply_tool_state(self, n: int) -> None:
        t = self.tool(n)
        value = {0: 0.0, 1: t.standby, 2: t.active}.get(t.state)
        if t.state == 0 or value is not None:
            for key in self.tool_heaters(n):
                self.set_target(key, value or 0.0)

    def set_hotend(self, raw, wait: bool) -> None:
        self.ready_cache = None
        p = self.floats(raw)
        temp = p.get("S")
        if temp is None:
            temp = p.get("R")
        tsel = p.get("T")
        if self.flavor == "rrf":
            # M104/M109 set the active temperature of tool T (default: the
            # current one); M109 also selects that tool (or the lowest-numbered
            # one when none is selected) before waiting.
            if tsel is not None:
                n = int(tsel)
            elif self.current is not None:
                n = self.current
            else:
                n = min(self.tools) if self.tools else 0
            if temp is not None:
                self.set_tool_temps(n, temp, None)
            if wait and self.current != n:
                self.select_tool(n)
            keys = self.tool_heaters(n)
        else:
            if tsel is not None:
                keys = [int(tsel)]
            else:
                n = self.active_tool()
                keys = self.tool_heaters(n if n is not None else 0)
            if temp is not None:
                for key in keys:
                    self.set_target(key, temp)
        if wait:
            self.sync()
            for key in keys:
                self.heater(key).waited = True
            # S waits only while heating, R both ways. Marlin's M109 without
            # either waits for nothing; RepRapFirmware's waits for the tool.
            if temp is not None or self.flavor == "rrf":
                self.heat_wait(keys, self.wait_rule(bed=False, cooling=p.get("S") is None and p.get("R") is not None))


# -- command handlers ---------------------------------------------------------

def _h_move(r: Replay, raw):
    r.do_move("G1", r.floats(raw))


def _h_arc(r: Replay, raw):
    r.arcs += 1
    if r.arcs == 1:
        r.warnings.append(f"line {r.line}: G2/G3 arcs are replayed as straight chords and left out of coverage")
    p = r.floats(raw)
    r.do_move("G1", {k: p.get(k) for k in ("X", "Y", "Z", "E", "F") if k in p}, arc=True)


def _h_dwell(r: Replay, raw):
    p = r.floats(raw)
    r.sync()
    if p.get("S") is not None:
        r.dwell += p["S"]
    elif p.get("P") is not None:
        r.dwell += p["P"] / 1000.0


def _h_g10(r: Replay, raw):
    if r.flavor == "rrf" and ("P" in raw or "L" in raw):
        # RepRapFirmware: G10 P<tool> [S<active>] [R<standby>] (and offsets);
        # G10 L<n> sets coordinate systems. Neither moves filament.
        if "L" not in raw and ("S" in raw or "R" in raw):
            n = int(_first(raw["P"], r.line, "P")) if raw.get("P") is not None else r.active_tool()
            if n is not None:
                r.set_tool_temps(n, _first(raw.get("S"), r.line, "S"), _first(raw.get("R"), r.line, "R"))
        return
    # Firmware retraction (Marlin G10 [S1]; RepRapFirmware G10 with no P).
    r.sync()
    r.fw_retract_count += 1
    r.check_hot(r.active_tool(), r.line, "firmware retraction (G10)")
    r.in_run = False


def _h_g11(r: Replay, raw):
    r.sync()
    r.check_hot(r.active_tool(), r.line, "firmware recovery (G11)")
    r.in_run = False


def _first(v: str | None, line: int, letter: str) -> float | None:
    if v is None:
        return None
    return _number(v.split(":")[0], line, letter)


def _h_units(r: Replay, raw, inch: bool):
    r.units = 25.4 if inch else 1.0


def _h_home(r: Replay, raw):
    r.sync()
    axes = [a for a in AXES if a in raw]
    if not axes:
        axes = list(AXES)
    for a in axes:
        i = AXES.index(a)
        r.pos[i] = None
        r.offset[i] = 0.0
    r.in_run = False


def _h_g92(r: Replay, raw):
    p = r.floats(raw)
    for i, a in enumerate(AXES):
        if a in p and p[a] is not None:
            v = p[a] * r.units
            if r.pos[i] is not None:
                machine = r.pos[i] + r.offset[i]
                r.offset[i] = machine - v
            r.pos[i] = v
    if "E" in p and p["E"] is not None:
        r.e = p["E"] * r.units
    r.in_run = False


def _h_m104(r: Replay, raw):
    r.set_hotend(raw, wait=False)


def _h_m109(r: Replay, raw):
    r.set_hotend(raw, wait=True)


def _h_m140(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is not None:
        r.set_target(BED, p["S"])


def _h_m190(r: Replay, raw):
    # M190 S<t> waits while heating, R<t> heating or cooling; neither: no wait.
    p = r.floats(raw)
    temp = p.get("S") if p.get("S") is not None else p.get("R")
    r.sync()
    if temp is not None:
        r.set_target(BED, temp)
        r.heat_wait([BED], r.wait_rule(bed=True, cooling=p.get("S") is None))


def _h_m116(r: Replay, raw):
    r.sync()
    r.ready_cache = None
    if "P" in raw and raw["P"] is not None:
        keys = r.tool_heaters(int(_first(raw["P"], r.line, "P")))
        timed: list[int | str] = list(keys)
    elif "H" in raw and raw["H"] is not None:
        keys = [int(_number(v, r.line, "H")) for v in raw["H"].split(":")]
        timed = list(keys)
    else:
        keys = list(r.heaters.keys())
        timed = keys + [BED]
    for key in keys:
        r.heater(key).waited = True
    # RepRapFirmware: every heater within the tolerance (S, default 2 degC) of
    # its target, heating or cooling; no residency; nothing below 40 degC.
    s = raw.get("S")
    tol = _number(s, r.line, "S") if s is not None else RRF_M116_TOLERANCE
    r.heat_wait(timed, WaitRule(True, tol, 0.0, 0.0, RRF_LOW_DONT_CARE))


def _h_m568(r: Replay, raw):
    n = int(_first(raw["P"], r.line, "P")) if raw.get("P") is not None else r.active_tool()
    if n is None:
        return
    r.set_tool_temps(n, _first(raw.get("S"), r.line, "S"), _first(raw.get("R"), r.line, "R"))
    if raw.get("A") is not None:
        # RepRapFirmware 3.3+: A0 off, A1 standby, A2 active.
        r.set_tool_state(n, int(_number(raw["A"], r.line, "A")))


def _h_m563(r: Replay, raw):
    if raw.get("P") is None:
        return
    n = int(_number(raw["P"], r.line, "P"))
    t = r.tool(n)
    r.ready_cache = None
    if raw.get("D") is not None:
        t.drives = [int(_number(v, r.line, "D")) for v in raw["D"].split(":")]
        if len(t.drives) > 1:
            r.mixing = True
    if raw.get("H") is not None:
        t.heaters = [int(_number(v, r.line, "H")) for v in raw["H"].split(":")]


def _record_mix(r: Replay, tool: int, factors: list[float], what: str) -> None:
    r.mix_commands += 1
    total = sum(factors)
    if abs(total - 1.0) > MIX_SUM_TOL:
        r.checks["mixes"].fail(r.line, f"{what} sums to {total:.4f}, not 1")
    r.mix_channels = max(r.mix_channels, len(factors))
    norm = [f / total for f in factors] if total > 0 else [0.0] * len(factors)
    t = r.tool(tool)
    if t.mix is None or len(t.mix) != len(norm) or any(abs(a - b) > 1e-9 for a, b in zip(t.mix, norm)):
        r.mix_changes += 1
    t.mix = norm


def _h_m163(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is None or p.get("P") is None:
        raise ParseError(r.line, "M163 needs S<channel> and P<factor>")
    r.collector[int(p["S"])] = p["P"]


def _h_m164(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is not None:
        vt = int(p["S"])
    else:
        vt = r.active_tool() or 0
    n = max(r.collector.keys(), default=-1) + 1
    factors = [r.collector.get(i, 0.0) for i in range(n)]
    _record_mix(r, vt, factors, f"M164 S{vt} mix {factors}")


def _h_m165(r: Replay, raw):
    p = r.floats(raw)
    letters = "ABCDHI"
    last = max((i for i, L in enumerate(letters) if p.get(L) is not None), default=-1)
    factors = [p.get(L) or 0.0 for L in letters[: last + 1]]
    for i, v in enumerate(factors):
        r.collector[i] = v
    tool = r.active_tool() or 0
    _record_mix(r, tool, factors, f"M165 mix {factors}")


def _h_m567(r: Replay, raw):
    n = int(_first(raw["P"], r.line, "P")) if raw.get("P") is not None else r.active_tool()
    if n is None or raw.get("E") is None:
        raise ParseError(r.line, "M567 needs E<a:b:...> (and a P tool or a selected tool)")
    factors = [_number(v, r.line, "E") for v in raw["E"].split(":")]
    t = r.tool(n)
    if t.drives and len(t.drives) == len(factors):
        full = [0.0] * (max(t.drives) + 1)
        for d, f in zip(t.drives, factors):
            full[d] = f
        factors_full = full
    else:
        factors_full = factors
    r.mixing = True
    r.ready_cache = None
    _record_mix(r, n, factors_full, f"M567 P{n} mix {factors}")


def _h_m204(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is not None:
        r.accel_print = r.accel_travel = p["S"]
    if p.get("P") is not None:
        r.accel_print = p["P"]
    if p.get("T") is not None:
        r.accel_travel = p["T"]
    if p.get("R") is not None:
        r.accel_retract = p["R"]


def _axis_values(r: Replay, raw, scale: float) -> dict[int, float]:
    out = {}
    for i, a in enumerate("XYZE"):
        v = raw.get(a)
        if v is not None:
            out[i] = _number(v.split(":")[0], r.line, a) * scale
    return out


def _h_m201(r: Replay, raw):
    for i, v in _axis_values(r, raw, 1.0).items():
        r.max_accel[i] = v
        r.limited = True


def _h_m203(r: Replay, raw):
    # Marlin: units per second; RepRapFirmware: mm/min unless S1.
    scale = 1.0
    if r.flavor == "rrf":
        s = raw.get("S")
        scale = 1.0 if (s is not None and _number(s, r.line, "S") == 1) else 1.0 / 60.0
    for i, v in _axis_values(r, raw, scale).items():
        r.max_speed[i] = v
        r.limited = True


def _h_m205(r: Replay, raw):
    p = {k: v for k, v in raw.items()}
    if p.get("J") is not None:
        r.jd = _number(p["J"], r.line, "J")
        r.jerk = None
    vals = _axis_values(r, raw, 1.0)
    if vals:
        _set_jerk(r, vals)


def _h_m566(r: Replay, raw):
    vals = _axis_values(r, raw, 1.0 / 60.0)
    if vals:
        _set_jerk(r, vals)


def _set_jerk(r: Replay, vals: dict[int, float]) -> None:
    if r.jerk is None:
        r.jerk = [math.inf, math.inf, DEFAULT_Z_JERK, DEFAULT_E_JERK]
    for i, v in vals.items():
        r.jerk[i] = v


def _h_m220(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is not None:
        r.speed_factor = p["S"] / 100.0


def _h_m221(r: Replay, raw):
    p = r.floats(raw)
    if p.get("S") is not None:
        r.flow_factor = p["S"] / 100.0


def _h_m200(r: Replay, raw):
    p = r.floats(raw)
    if p.get("D") is not None:
        r.volumetric = p["D"] > 0
        if r.volumetric:
            r.warnings.append(f"line {r.line}: volumetric extrusion (M200 D{p['D']:g}): E read as mm^3")


def _h_m302(r: Replay, raw):
    r.warnings.append(f"line {r.line}: M302 (cold extrusion settings) ignored; the checker keeps --min-extrude-temp")


def _h_rel(r: Replay, raw, absolute: bool):
    r.abs_xyz = absolute


def _h_e_mode(r: Replay, raw, relative: bool):
    r.m83 = relative


def _h_sync(r: Replay, raw):
    r.sync()


def _h_ignore(r: Replay, raw):
    pass


_HANDLERS = {
    "G0": _h_move, "G1": _h_move, "G2": _h_arc, "G3": _h_arc, "G4": _h_dwell,
    "G10": _h_g10, "G11": _h_g11,
    "G20": lambda r, raw: _h_units(r, raw, True), "G21": lambda r, raw: _h_units(r, raw, False),
    "G28": _h_home, "G90": lambda r, raw: _h_rel(r, raw, True), "G91": lambda r, raw: _h_rel(r, raw, False),
    "G92": _h_g92,
    "M82": lambda r, raw: _h_e_mode(r, raw, False), "M83": lambda r, raw: _h_e_mode(r, raw, True),
    "M104": _h_m104, "M109": _h_m109, "M140": _h_m140, "M190": _h_m190, "M116": _h_m116,
    "M106": _h_ignore, "M107": _h_ignore,
    "M163": _h_m163, "M164": _h_m164, "M165": _h_m165,
    "M563": _h_m563, "M567": _h_m567, "M568": _h_m568,
    "M200": _h_m200, "M201": _h_m201, "M203": _h_m203, "M204": _h_m204, "M205": _h_m205,
    "M220": _h_m220, "M221": _h_m221, "M302": _h_m302, "M400": _h_sync, "M566": _h_m566,
}


# ---------------------------------------------------------------------------
# Time replay
# ---------------------------------------------------------------------------

def replay_time(moves: list[tuple], jd: float, jerk: list[float] | None,
                breakdown: dict[str, float] | None = None, times: list[float] | None = None) -> float:
    """Total time of the moves with trapezoidal profiles and a look-ahead
    (the speeds of ``plan_speeds``, each move timed by ``trapezoid_time``).
    ``breakdown``, when given, receives the time of printing moves (XYZ with
    E), travel (XYZ without E) and E-only moves (retractions and recoveries);
    ``times``, when given, each move's time in order.
    """
    n = len(moves)
    if n == 0:
        return 0.0
    vin, vout = plan_speeds(moves, jd, jerk)
    total = 0.0
    kinds = {"print": 0.0, "travel": 0.0, "e_only": 0.0}
    for i in range(n):
        m = moves[i]
        t = trapezoid_time(m[0], vin[i], vout[i], m[1], m[2])
        total += t
        if breakdown is not None:
            kinds["e_only" if m[6] != 0.0 else ("print" if m[10] != 0.0 else "travel")] += t
        if times is not None:
            times.append(t)
    if breakdown is not None:
        breakdown.update(kinds)
    return total


def heating_waits(r: Replay, times: list[float]) -> tuple[float, list[dict]]:
    """Total time of the file's heating waits, and each wait that took time
    (``{"line", "wait_s"}``), from the heating model.

    Every heater starts at ``--ambient`` at time 0. A target change or a wait
    happens at the machine time of its line: the time of the moves before it
    (``times``, from the look-ahead over the whole file; a wait empties the
    planner, so nothing after it changes the moves before it), plus the dwells
    and earlier waits before it. From a target change on, the heater moves
    linearly toward its target (``Ramp``); a wait lasts until every heater it
    names is done by its rule (``Ramp.wait``), and that time is a dwell there.
    """
    model = HeatingModel(r.o)
    before = list(accumulate(times, initial=0.0))
    waited = 0.0
    waits: list[dict] = []
    for ev in r.heat_events:
        w = model.apply(before[ev[1]] + ev[2] + waited, ev)
        if w > 0.0:
            waited += w
            waits.append({"line": ev[3], "wait_s": w})
    return waited, waits


def plan_speeds(moves: list[tuple], jd: float, jerk: list[float] | None) -> tuple[list[float], list[float]]:
    """Entry and exit speed of every move under the look-ahead.

    Junction speed limits follow Marlin's junction deviation: with theta the
    angle between the two paths (cos theta = -u_in . u_out), the junction is
    taken at v = sqrt(a * jd * s / (1 - s)), s = sin(theta / 2), a the
    outgoing move's acceleration. When ``jerk`` (X, Y, Z, E in mm/s) is given
    instead, v is the largest common speed whose per-axis velocity change
    |v * (c_out - c_in)| stays within the jerk limits. Junctions never exceed
    either move's nominal speed. A move that starts or ends at a stop (start
    or end of file, dwell, wait, tool change, homing) does so at rest with
    junction deviation, or at its jerk "safe speed" (largest speed whose
    per-axis components are within the jerk limits) with jerk. A backward pass
    then caps each entry speed by what the move can still brake from, a
    forward pass by what it can reach, and each move takes the time of its
    trapezoid (or triangle): the exit speed returned is the one the move
    really ends at (never above the next move's entry speed).
    """
    n = len(moves)
    if n == 0:
        return [], []
    L = [m[0] for m in moves]
    V = [m[1] for m in moves]
    A = [m[2] for m in moves]

    def safe(m: tuple) -> float:
        if jerk is None:
            return 0.0
        v = m[1]
        for k in range(4):
            c = abs(m[7 + k])
            if c > 1e-12 and jerk[k] / c < v:
                v = jerk[k] / c
        return v

    entry_lim = [0.0] * n
    exit_lim = [0.0] * n
    shared = [False] * n
    prev = None
    for i, m in enumerate(moves):
        if prev is None or m[11]:
            entry_lim[i] = safe(m)
            if prev is not None:
                exit_lim[i - 1] = safe(prev)
        else:
            shared[i] = True
            if jerk is None:
                cos_theta = -(prev[3] * m[3] + prev[4] * m[4] + prev[5] * m[5] + prev[6] * m[6])
                if cos_theta > 0.999999:
                    v = 0.0
                elif cos_theta < -0.999999:
                    v = math.inf
                else:
                    sin_half = math.sqrt(0.5 * (1.0 - cos_theta))
                    v = math.sqrt(m[2] * jd * sin_half / (1.0 - sin_half))
            else:
                v = math.inf
                for k in range(7, 11):
                    dc = abs(m[k] - prev[k])
                    if dc > 1e-12 and jerk[k - 7] / dc < v:
                        v = jerk[k - 7] / dc
            v = min(v, prev[1], m[1])
            entry_lim[i] = v
            exit_lim[i - 1] = v
        prev = m
    exit_lim[n - 1] = safe(moves[n - 1])
    vin = [0.0] * n
    vout = [0.0] * n
    sqrt = math.sqrt
    # Backward pass: each move must be able to brake to its exit speed.
    for i in range(n - 1, -1, -1):
        vo = vin[i + 1] if (i + 1 < n and shared[i + 1]) else exit_lim[i]
        if vo > exit_lim[i]:
            vo = exit_lim[i]
        if vo > V[i]:
            vo = V[i]
        vout[i] = vo
        vi = sqrt(vo * vo + 2.0 * A[i] * L[i])
        if vi > entry_lim[i]:
            vi = entry_lim[i]
        if vi > V[i]:
            vi = V[i]
        vin[i] = vi
    # Forward pass: each move must be able to reach its exit speed.
    for i in range(n):
        if shared[i] and vin[i] > vout[i - 1]:
            vin[i] = vout[i - 1]
        vo = sqrt(vin[i] * vin[i] + 2.0 * A[i] * L[i])
        if vout[i] > vo:
            vout[i] = vo
    for i in range(n - 1):
        if shared[i + 1] and vin[i + 1] < vout[i]:
            vout[i] = vin[i + 1]
    return vin, vout


def trapezoid_time(length: float, v0: float, v1: float, vmax: float, accel: float) -> float:
    """Time to cover ``length`` starting at v0, ending at v1, cruising at most
    at vmax, accelerating and braking at ``accel``."""
    if length <= 0:
        return 0.0
    if accel <= 0 or not math.isfinite(accel):
        return length / vmax
    v0 = min(v0, vmax)
    v1 = min(v1, vmax)
    d_acc = (vmax * vmax - v0 * v0) / (2.0 * accel)
    d_dec = (vmax * vmax - v1 * v1) / (2.0 * accel)
    if d_acc + d_dec <= length:
        return (vmax - v0) / accel + (vmax - v1) / accel + (length - d_acc - d_dec) / vmax
    vp2 = accel * length + 0.5 * (v0 * v0 + v1 * v1)
    vp = math.sqrt(max(vp2, max(v0, v1) ** 2))
    return max(0.0, (vp - v0) / accel) + max(0.0, (vp - v1) / accel)


def trapezoid_phases(length: float, v0: float, v1: float, vmax: float,
                     accel: float) -> tuple[float, float, float, float, float, float]:
    """The profile ``trapezoid_time`` times, as its phases: (v0, peak speed,
    v1, accelerating time, cruising time, braking time). Distance along the
    move at time t of a phase is a quadratic in t (constant acceleration
    +accel, 0, -accel). An infinite or non-positive acceleration gives one
    cruise at vmax."""
    if length <= 0:
        return (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    if accel <= 0 or not math.isfinite(accel):
        return (vmax, vmax, vmax, 0.0, length / vmax, 0.0)
    v0 = min(v0, vmax)
    v1 = min(v1, vmax)
    d_acc = (vmax * vmax - v0 * v0) / (2.0 * accel)
    d_dec = (vmax * vmax - v1 * v1) / (2.0 * accel)
    if d_acc + d_dec <= length:
        return (v0, vmax, v1, (vmax - v0) / accel, (length - d_acc - d_dec) / vmax, (vmax - v1) / accel)
    vp2 = accel * length + 0.5 * (v0 * v0 + v1 * v1)
    vp = math.sqrt(max(vp2, max(v0, v1) ** 2))
    return (v0, vp, v1, max(0.0, (vp - v0) / accel), 0.0, max(0.0, (vp - v1) / accel))


# ---------------------------------------------------------------------------
# Mesh: volume and cross-sections
# ---------------------------------------------------------------------------

def load_mesh(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (merged) and triangles of a mesh file, via trimesh."""
    import trimesh

    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as exc:  # noqa: BLE001 - any loader failure is a usage error
        raise UsageError(f"cannot load mesh {path}: {exc}") from exc
    if not hasattr(mesh, "faces") or len(mesh.faces) == 0:
        raise UsageError(f"mesh {path} has no triangles")
    mesh.merge_vertices()
    return np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces, dtype=np.int64)


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Volume by the signed-tetrahedron sum (origin to each triangle)."""
    a = vertices[faces[:, 0]]
    b = vertices[faces[:, 1]]
    c = vertices[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


class MeshSlicer:
    """Horizontal cross-sections of a triangle mesh as shapely geometry.

    Each crossing edge gets one intersection point, shared by both triangles
    on it, so the section's segments chain into closed loops exactly; loops
    are combined even-odd (symmetric difference), which turns nested loops
    into holes.
    """

    def __init__(self, vertices: np.ndarray, faces: np.ndarray):
        self.v = vertices
        self.f = faces
        e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
        e.sort(axis=1)
        self.edges, inverse = np.unique(e, axis=0, return_inverse=True)
        self.face_edges = inverse.reshape(3, -1).T  # (F, 3)
        self.open_chains = 0

    def section(self, z: float):
        import shapely

        v, edges = self.v, self.edges
        d = v[:, 2] - z
        if np.any(np.abs(d) < 1e-9):
            z += 1e-7
            d = v[:, 2] - z
        above = d > 0
        ea, eb = edges[:, 0], edges[:, 1]
        crossing = above[ea] != above[eb]
        if not crossing.any():
            return shapely.Polygon()
        pts = np.zeros((len(edges), 2))
        ca, cb = ea[crossing], eb[crossing]
        t = d[ca] / (d[ca] - d[cb])
        pts[crossing] = v[ca][:, :2] + (v[cb][:, :2] - v[ca][:, :2]) * t[:, None]
        fe = self.face_edges
        fc = crossing[fe]  # (F, 3)
        sel = fc.sum(axis=1) == 2
        fe2 = fe[sel]
        fc2 = fc[sel]
        pairs = fe2[fc2].reshape(-1, 2)
        adj: dict[int, list[int]] = {}
        for a, b in pairs.tolist():
            adj.setdefault(a, []).append(b)
            adj.setdefault(b, []).append(a)
        seen: set[int] = set()
        rings = []
        for start in adj:
            if start in seen:
                continue
            loop = [start]
            seen.add(start)
            prev, cur = None, start
            closed = False
            while True:
                nxt = None
                for cand in adj[cur]:
                    if cand != prev and cand not in seen:
                        nxt = cand
                        break
                if nxt is None:
                    closed = start in adj[cur] and len(loop) > 2
                    break
                seen.add(nxt)
                loop.append(nxt)
                prev, cur = cur, nxt
            if not closed:
                self.open_chains += 1
                continue
            coords = pts[loop]
            poly = shapely.Polygon(coords)
            if not poly.is_valid:
                poly = shapely.make_valid(poly)
            if poly.area > 0:
                rings.append(poly)
        if not rings:
            return shapely.Polygon()
        rings.sort(key=lambda g: -g.area)
        return reduce(lambda acc, g: acc.symmetric_difference(g), rings[1:], rings[0])


def bead_geometry(segs: list[tuple], height: float, area: float, ends: str = "flat"):
    """Beads of PART segments: their union, summed area, the overlap of
    consecutive segments of one run, and the widths.

    ``ends="flat"`` (the contract) makes each bead a flat-ended rectangle;
    ``"round"`` the segment swept by a disc of the bead's width (a stadium),
    closer to what a round nozzle lays at corners. With round ends a continuous
    run is one bead: the area its own segments share is not overlap."""
    import shapely

    arr = np.asarray([s[:5] for s in segs], dtype=float)
    runs = np.asarray([s[5] for s in segs])
    x0, y0, x1, y1, efil = arr.T
    dx = x1 - x0
    dy = y1 - y0
    ln = np.hypot(dx, dy)
    keep = ln > 1e-9
    x0, y0, x1, y1, efil, dx, dy, ln, runs = (a[keep] for a in (x0, y0, x1, y1, efil, dx, dy, ln, runs))
    width = efil * area / (ln * height)
    nx = -dy / ln * width / 2.0
    ny = dx / ln * width / 2.0
    ring = np.stack([
        np.stack([x0 + nx, y0 + ny], axis=1),
        np.stack([x1 + nx, y1 + ny], axis=1),
        np.stack([x1 - nx, y1 - ny], axis=1),
        np.stack([x0 - nx, y0 - ny], axis=1),
        np.stack([x0 + nx, y0 + ny], axis=1),
    ], axis=1)
    if ends == "round":
        lines = shapely.linestrings(np.stack([np.stack([x0, y0], axis=1), np.stack([x1, y1], axis=1)], axis=1))
        rects = shapely.buffer(lines, width / 2.0, quad_segs=8)
        bead_area = float(shapely.area(rects).sum())
    else:
        rects = shapely.polygons(ring)
        bead_area = float((width * ln).sum())
    if ends == "round":
        # A continuous extrusion is one bead: where its own segments meet (joints,
        # and the tight turns of a densely sampled centre line) the nozzle lays no
        # second layer of material. Each run's footprint is the union of its
        # segments; what the footprints of different runs share is overlap. The
        # layer's union is that of the footprints (the same set, fewer pieces).
        order = np.argsort(runs, kind="stable")
        bounds = np.flatnonzero(np.diff(runs[order])) + 1
        groups = np.split(order, bounds)
        footprints = [shapely.union_all(rects[g]) for g in groups]
        run_area = float(sum(f.area for f in footprints))
        consecutive = bead_area - run_area
        return shapely.union_all(footprints), bead_area, consecutive, width
    union = shapely.union_all(rects)
    same = runs[1:] == runs[:-1]
    consecutive = 0.0
    if same.any():
        idx = np.nonzero(same)[0]
        consecutive = float(shapely.area(shapely.intersection(rects[idx], rects[idx + 1])).sum())
    return union, bead_area, consecutive, width


# ---------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------

_M596_RE = re.compile(r"^\s*(?:N\d+\s*)?M596\b", re.MULTILINE | re.IGNORECASE)


def uses_motion_systems(text: str) -> bool:
    """A file that selects motion systems (RepRapFirmware 3.5 ``M596``)."""
    return _M596_RE.search(text) is not None


def analyse(text: str, opts: Options, name: str = "<string>") -> dict:
    """Replays ``text`` and returns the report dictionary (raises ParseError).
    A file with ``M596`` (multiple motion systems) is replayed stream by
    stream by ``multi_motion``."""
    if uses_motion_systems(text):
        import multi_motion

        return multi_motion.analyse_multi(text, opts, name)
    r = Replay(opts)
    r.run(text)
    return build_report(r, opts, name)


def build_report(r: Replay, o: Options, name: str) -> dict:
    checks = r.checks
    # Parse: unknown commands are informational.
    checks["parse"].details["unknown_commands"] = dict(sorted(r.unknown.items()))

    # Layers: Z never decreases; heights.
    prev_z = None
    layer_rows = []
    for lay in r.layers:
        if lay.z is not None:
            if prev_z is not None and lay.z < prev_z - LAYER_Z_TOL:
                checks["layers"].fail(lay.line, f"layer {lay.number} at Z {lay.z:.4f} is below the previous layer's Z {prev_z:.4f}")
            lay.height = lay.z - prev_z if prev_z is not None else lay.z
            prev_z = lay.z
        layer_rows.append(lay)
    if not r.layers:
        checks["layers"].skip("no ;LAYER: markers")

    # Features
    if not any(v > 0 for v in r.volume_by_type.values()):
        checks["features"].skip("no extrusion")

    # Bed
    if o.bed_rect is None and o.bed_circle is None:
        checks["bed"].skip("no --bed or --bed-circle given")
    if r.mix_commands == 0:
        checks["mixes"].skip("no mix commands")

    # Volume
    part_volume = r.volume_by_type.get("PART", 0.0)
    volume = {
        "filament_diameter_mm": o.filament,
        "filament_area_mm2": r.area,
        "by_type_mm3": {k: round(v, 6) for k, v in sorted(r.volume_by_type.items())},
        "part_mm3": part_volume,
        "mesh_mm3": None,
        "ratio": None,
        "tolerance": o.volume_tol,
    }
    mesh_data = None
    if o.mesh is not None:
        vtx, fcs = load_mesh(o.mesh)
        mvol = abs(mesh_volume(vtx, fcs))
        volume["mesh_mm3"] = mvol
        ratio = part_volume / mvol if mvol > 0 else None
        volume["ratio"] = ratio
        if ratio is None or abs(ratio - 1.0) > o.volume_tol:
            checks["volume"].fail(None, f"PART volume {part_volume:.3f} mm^3 is {ratio if ratio is not None else float('nan'):.4f} x the mesh volume {mvol:.3f} mm^3 (tolerance {o.volume_tol:g})")
        mesh_data = (vtx, fcs)
    else:
        checks["volume"].skip("no --mesh given")
    checks["volume"].details.update({"part_mm3": part_volume, "mesh_mm3": volume["mesh_mm3"], "ratio": volume["ratio"]})

    # Coverage
    coverage = {"every": o.coverage_every, "bead_ends": o.bead_ends, "layers": [], "worst_coverage": None, "worst_overlap": None,
                "min": o.coverage_min, "overlap_max": o.overlap_max, "placement": None}
    if mesh_data is not None:
        coverage_check(r, o, mesh_data, coverage)
    else:
        checks["coverage"].skip("no --mesh given")

    # Time
    by_kind: dict[str, float] = {}
    times: list[float] | None = [] if r.heat_on else None
    replayed = replay_time(r.moves, r.jd, r.jerk, by_kind, times) + r.dwell
    heating_s, waits = heating_waits(r, times) if times is not None else (0.0, [])
    replayed += heating_s
    time_tol = time_tolerance(o)
    time = {
        "replayed_s": replayed,
        "estimated_s": r.estimated_time,
        "estimate_line": r.estimated_time_line,
        "rel_error": None,
        "tolerance": time_tol,
        "moves": len(r.moves),
        "dwell_s": r.dwell - r.tool_change_s,
        "heating_wait_s": heating_s,
        "tool_change_s": r.tool_change_s,
        "heating_waits": waits[:MAX_EXAMPLES],
        "heating_model": heating_model(r),
        "by_kind_s": by_kind,
        "junction": ("jerk" if r.jerk is not None else f"junction deviation {r.jd:g} mm"),
        "accel_print": r.accel_print, "accel_travel": r.accel_travel, "accel_retract": r.accel_retract,
        "firmware_retractions_untimed": r.fw_retract_count,
    }
    if r.estimated_time is None:
        checks["time"].skip("no '; estimated printing time: <seconds> s' line")
    else:
        rel = (r.estimated_time - replayed) / replayed if replayed > 0 else (0.0 if r.estimated_time == 0 else math.inf)
        time["rel_error"] = rel
        if abs(rel) > time_tol:
            checks["time"].fail(r.estimated_time_line, f"file estimates {r.estimated_time:.1f} s, replay gives {replayed:.1f} s ({rel * 100:+.1f} %)")
    checks["time"].details.update({"replayed_s": replayed, "estimated_s": r.estimated_time, "rel_error": time["rel_error"]})

    # Heating never skipped; parse always passes here.
    tools = {
        "changes": r.tool_changes,
        "selections": len(r.tool_selects),
        "first_selections": r.tool_selects[:20],
        "filament_mm": {f"T{k}" if k >= 0 else "none": v for k, v in sorted(r.filament_by_tool.items())},
        "volume_mm3": {f"T{k}" if k >= 0 else "none": v * r.area for k, v in sorted(r.filament_by_tool.items())},
    }
    channels = {
        "filament_mm": {str(k): v for k, v in sorted(r.filament_by_channel.items())},
        "volume_mm3": {str(k): v * r.area for k, v in sorted(r.filament_by_channel.items())},
    }

    def bbox(e):
        return None if not math.isfinite(e[0]) else {"x_min": e[0], "y_min": e[1], "x_max": e[2], "y_max": e[3],
                                                       "width": e[2] - e[0], "depth": e[3] - e[1]}

    zs = [lay.z for lay in r.layers if lay.z is not None]
    report = {
        "file": name,
        "mode": "single",
        "ok": all(c.status != "fail" for c in checks.values()),
        "flavor": r.flavor,
        "flavor_from": r.flavor_from,
        "mixing": r.mixing,
        "lines": r.line,
        "checks": {k: c.to_json() for k, c in checks.items()},
        "layers": {
            "count": len(r.layers),
            "with_extrusion": len(zs),
            "z_first": zs[0] if zs else None,
            "z_last": zs[-1] if zs else None,
        },
        "volume": volume,
        "coverage": coverage,
        "time": time,
        "tools": tools,
        "mix": {"commands": r.mix_commands, "changes": r.mix_changes, "channels": r.mix_channels},
        "channels": channels,
        "extents": {"moves": bbox(r.extents["moves"]), "extrusion": bbox(r.extents["extrusion"])},
        "unknown_commands": dict(sorted(r.unknown.items())),
        "warnings": r.warnings[:MAX_EXAMPLES],
        "options": options_report(o, time_tol),
    }
    return report


def heating_model(r: Replay) -> dict | None:
    """The heating model's parameters as this file's waits used them (None
    when it is off)."""
    if not r.heat_on:
        return None
    o = r.o
    hot, bed = r.wait_rule(bed=False, cooling=False), r.wait_rule(bed=True, cooling=False)
    return {
        "heating_rate": o.heating_rate, "cooling_rate": o.cooling_rate,
        "bed_heating_rate": o.bed_heating_rate, "bed_cooling_rate": BED_COOLING_RATE,
        "residency_s": hot.residency, "bed_residency_s": bed.residency,
        "window": hot.window, "bed_window": bed.window, "ambient": o.ambient,
    }


def options_report(o: Options, time_tol: float) -> dict:
    """The options every report states, with the time tolerance applied."""
    return {
        "mesh": o.mesh, "place": o.place, "bed": o.bed_rect, "bed_circle": o.bed_circle,
        "filament": o.filament, "min_extrude_temp": o.min_extrude_temp,
        "volume_tol": o.volume_tol, "coverage_min": o.coverage_min, "overlap_max": o.overlap_max,
        "coverage_every": o.coverage_every, "bead_ends": o.bead_ends, "time_tol": time_tol,
        "accel": list(o.accel), "junction_deviation": o.junction_deviation,
        "heating_rate": o.heating_rate, "cooling_rate": o.cooling_rate, "bed_heating_rate": o.bed_heating_rate,
        "residency": o.residency, "bed_residency": o.bed_residency, "ambient": o.ambient,
        "tool_change_time": o.tool_change_time,
    }


def placement_target(o: Options, mesh_centre: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
    """Where the mesh's XY bounding-box centre goes (``--place``)."""
    if o.place.lower() == "keep":
        return mesh_centre
    if o.place.lower() in ("centre", "center"):
        if o.bed_rect is not None:
            x0, y0, x1, y1 = o.bed_rect
            return ((x0 + x1) / 2.0, (y0 + y1) / 2.0)
        if o.bed_circle is not None:
            return (o.bed_circle[0], o.bed_circle[1])
        return (0.0, 0.0)
    x, y = o.place.split(",")
    return (float(x), float(y))


def coverage_check(r: Replay, o: Options, mesh_data, coverage: dict) -> None:
    import shapely

    vtx, fcs = mesh_data
    lo = vtx.min(axis=0)
    hi = vtx.max(axis=0)
    cx, cy = (lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0
    tx, ty = placement_target(o, (cx, cy))
    shift = np.array([tx - cx, ty - cy, -lo[2]])
    slicer = MeshSlicer(vtx + shift, fcs)
    coverage["placement"] = {"mesh_bbox_centre": [cx, cy], "target": [tx, ty], "z_offset": float(-lo[2])}
    check = r.checks["coverage"]
    worst_cov = None
    worst_ovl = None
    for lay in r.layers:
        if not lay.sampled:
            continue
        row = {"layer": lay.number, "line": lay.line, "z": lay.z, "height": lay.height,
               "coverage": None, "overlap": None, "reference_mm2": 0.0, "bead_mm2": 0.0, "union_mm2": 0.0,
               "outside_mm2": 0.0, "segments": len(lay.segs)}
        if lay.z is None or lay.height is None or lay.height <= 0:
            if lay.segs:
                check.fail(lay.line, f"layer {lay.number}: beads but no usable layer height")
            row["note"] = "no extrusion"
            coverage["layers"].append(row)
            continue
        ref = slicer.section(lay.z - lay.height / 2.0)
        ref_area = float(ref.area)
        row["reference_mm2"] = ref_area
        if lay.segs:
            union, bead_area, consecutive, _ = bead_geometry(lay.segs, lay.height, r.area if not r.volumetric else 1.0,
                                                             o.bead_ends)
            uarea = float(union.area)
            row["bead_mm2"] = bead_area
            row["union_mm2"] = uarea
            overlap = max(0.0, bead_area - uarea - consecutive) / bead_area if bead_area > 0 else 0.0
            row["overlap"] = overlap
            if ref_area > 0:
                row["coverage"] = float(shapely.intersection(union, ref).area) / ref_area
                row["outside_mm2"] = float(shapely.difference(union, ref).area)
        elif ref_area > 0:
            row["coverage"] = 0.0
        if row["coverage"] is not None:
            if row["coverage"] < o.coverage_min:
                check.fail(lay.line, f"layer {lay.number} (Z {lay.z:.3f}): coverage {row['coverage']:.4f} < {o.coverage_min:g}")
            if worst_cov is None or row["coverage"] < worst_cov["coverage"]:
                worst_cov = {"layer": lay.number, "coverage": row["coverage"]}
        if row["overlap"] is not None:
            if row["overlap"] > o.overlap_max:
                check.fail(lay.line, f"layer {lay.number} (Z {lay.z:.3f}): overlap {row['overlap']:.4f} > {o.overlap_max:g}")
            if worst_ovl is None or row["overlap"] > worst_ovl["overlap"]:
                worst_ovl = {"layer": lay.number, "overlap": row["overlap"]}
        coverage["layers"].append(row)
    coverage["worst_coverage"] = worst_cov
    coverage["worst_overlap"] = worst_ovl
    if slicer.open_chains:
        coverage["open_section_chains"] = slicer.open_chains
    if not coverage["layers"]:
        check.skip("no sampled layers")
    check.details.update({"sampled_layers": len(coverage["layers"]), "worst_coverage": worst_cov, "worst_overlap": worst_ovl})


# ---------------------------------------------------------------------------
# Summary and command line
# ---------------------------------------------------------------------------

def summary(rep: dict) -> str:
    if rep.get("mode") == "multi-motion":
        import multi_motion

        return multi_motion.summary_multi(rep)
    out = []
    out.append(f"{rep['file']}: {rep['lines']} lines, flavour {rep['flavor']} ({rep['flavor_from']})"
               + (", mixing" if rep["mixing"] else ""))
    lay = rep["layers"]
    out.append(f"layers: {lay['count']} ({lay['with_extrusion']} with extrusion), Z {lay['z_first']} .. {lay['z_last']}")
    ext = rep["extents"]["extrusion"]
    if ext:
        out.append(f"extrusion extents: X {ext['x_min']:.3f} .. {ext['x_max']:.3f}, Y {ext['y_min']:.3f} .. {ext['y_max']:.3f}")
    vol = rep["volume"]
    bytype = ", ".join(f"{k} {v:.1f}" for k, v in vol["by_type_mm3"].items()) or "none"
    out.append(f"volume by type (mm^3): {bytype}")
    if vol["mesh_mm3"] is not None:
        out.append(f"PART {vol['part_mm3']:.1f} mm^3 vs mesh {vol['mesh_mm3']:.1f} mm^3: ratio {vol['ratio']:.4f}")
    tools = rep["tools"]
    fil = ", ".join(f"{k} {v:.1f} mm" for k, v in tools["filament_mm"].items())
    out.append(f"tools: {tools['changes']} changes; filament {fil}")
    if rep["channels"]["filament_mm"]:
        ch = ", ".join(f"ch{k} {v:.1f} mm" for k, v in rep["channels"]["filament_mm"].items())
        out.append(f"mix channels: {ch}; {rep['mix']['commands']} mix commands, {rep['mix']['changes']} changes")
    t = rep["time"]
    est = f"{t['estimated_s']:.1f} s" if t["estimated_s"] is not None else "none"
    k = t.get("by_kind_s") or {}
    out.append(f"time: replayed {t['replayed_s']:.1f} s (print {k.get('print', 0):.0f}, travel {k.get('travel', 0):.0f}, "
               f"E-only {k.get('e_only', 0):.0f}, dwell {t['dwell_s']:.0f}, heating waits {t['heating_wait_s']:.0f}"
               + ("" if t["heating_model"] else " (not modelled)")
               + f", tool changes {t['tool_change_s']:.0f}), file estimate {est}")
    cov = rep["coverage"]
    if cov["layers"]:
        wc = cov["worst_coverage"]
        wo = cov["worst_overlap"]
        out.append(f"coverage: {len(cov['layers'])} sampled layers; worst coverage "
                   f"{'%.4f (layer %s)' % (wc['coverage'], wc['layer']) if wc else 'n/a'}; worst overlap "
                   f"{'%.4f (layer %s)' % (wo['overlap'], wo['layer']) if wo else 'n/a'}")
    if rep["unknown_commands"]:
        out.append("unknown commands: " + ", ".join(f"{k} x{v}" for k, v in rep["unknown_commands"].items()))
    out.extend(checks_summary(rep, 9))
    return "\n".join(out)


def checks_summary(rep: dict, name_width: int) -> list[str]:
    """The checks' lines of a summary (status, violations, the first examples) and
    the result line; shared by the single- and multi-stream summaries."""
    out = ["checks:"]
    for name, c in rep["checks"].items():
        line = f"  {name:{name_width}s} {c['status'].upper():7s}"
        if c["violations"]:
            line += f" {c['violations']} violation(s)"
        if c.get("skipped"):
            line += f" ({c['skipped']})"
        out.append(line)
        for ex in c["examples"][:5]:
            where = f"line {ex['line']}" if ex["line"] is not None else "file"
            out.append(f"      {where}: {ex['message']}")
        if c["violations"] > 5:
            out.append(f"      ... {c['violations'] - 5} more")
    out.append("RESULT: " + ("PASS" if rep["ok"] else "FAIL"))
    return out


def _floats(text: str, n: int, what: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        raise UsageError(f"{what}: expected {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n:
        raise UsageError(f"{what}: expected {n} comma-separated numbers, got {text!r}")
    return vals


def parse_args(argv: list[str]) -> tuple[str, Options, str | None]:
    ap = argparse.ArgumentParser(
        prog="gcode_replay.py",
        description="Replay a G-code file as a printer would and check it (see the module docstring).")
    ap.add_argument("file", help="G-code file")
    ap.add_argument("--mesh", help="the part's mesh (STL/OBJ/3MF...) for the volume and coverage checks")
    ap.add_argument("--place", default="centre",
                    help="where the mesh's XY bounding-box centre goes: 'centre' (the bed's centre; the origin "
                         "without a bed), X,Y, or 'keep' (the mesh's own coordinates); its lowest point goes to Z 0")
    bed = ap.add_mutually_exclusive_group()
    bed.add_argument("--bed", help="bed rectangle X0,Y0,X1,Y1 (mm)")
    bed.add_argument("--bed-circle", help="round bed CX,CY,R (mm)")
    ap.add_argument("--filament", type=float, default=1.75, help="filament diameter (mm), default 1.75")
    ap.add_argument("--min-extrude-temp", type=float, default=DEFAULT_MIN_EXTRUDE_TEMP,
                    help="cold-extrusion limit (degC), default 170 (Marlin EXTRUDE_MINTEMP)")
    ap.add_argument("--volume-tol", type=float, default=0.02, help="relative volume tolerance, default 0.02")
    ap.add_argument("--coverage-min", type=float, default=0.99, help="minimum coverage per sampled layer, default 0.99")
    ap.add_argument("--overlap-max", type=float, default=0.05, help="maximum bead overlap per sampled layer, default 0.05")
    ap.add_argument("--coverage-every", type=int, default=5, help="sample every N-th layer for coverage, default 5")
    ap.add_argument("--bead-ends", choices=("flat", "round"), default="flat",
                    help="beads as flat-ended rectangles (default) or with round ends (swept disc)")
    ap.add_argument("--time-tol", type=float, default=None,
                    help="relative time tolerance, default 0.05 (0.02 with multiple motion systems)")
    ap.add_argument("--flavor", choices=("marlin", "rrf"), help="firmware (default: the '; flavor:' header, else marlin)")
    ap.add_argument("--accel", default=None,
                    help="default accelerations P[,T[,R]] in mm/s^2 before any M204 (default 3000, Marlin's stock value)")
    ap.add_argument("--junction-deviation", type=float, default=DEFAULT_JUNCTION_DEVIATION,
                    help="junction deviation (mm) before any M205 J, default 0.013")
    heat = ap.add_argument_group("heating waits and tool changes in the time replay (without --heating-rate "
                                 "M109/M190/M116 waits take 0 s)")
    heat.add_argument("--heating-rate", type=float, metavar="DEGC_S",
                      help="hotends heat at this rate (degC/s): turns the heating model on")
    heat.add_argument("--cooling-rate", type=float, metavar="DEGC_S",
                      help=f"hotends cool at this rate (degC/s), default {DEFAULT_COOLING_RATE:g}")
    heat.add_argument("--bed-heating-rate", type=float, metavar="DEGC_S",
                      help=f"the bed heats at this rate (degC/s), default {DEFAULT_BED_HEATING_RATE:g} "
                           f"(it cools at {BED_COOLING_RATE:g})")
    heat.add_argument("--residency", type=float, metavar="S",
                      help="M109 holds this long once at temperature (Marlin TEMP_RESIDENCY_TIME), "
                           f"default {MARLIN_RESIDENCY:g} for Marlin, 0 for RepRapFirmware")
    heat.add_argument("--bed-residency", type=float, metavar="S",
                      help="the same for M190 (Marlin TEMP_BED_RESIDENCY_TIME), same defaults")
    heat.add_argument("--ambient", type=float, metavar="DEGC",
                      help=f"every heater's temperature at the start (degC), default {DEFAULT_AMBIENT:g}")
    heat.add_argument("--tool-change-time", type=float, default=0.0, metavar="S",
                      help="dwell of each change of tool (T<n> to another tool; not T-1, not the same tool), "
                           "default 0")
    mm = ap.add_argument_group("multiple motion systems (RepRapFirmware 3.5 M596; override the file's header)")
    mm.add_argument("--head-radius", type=float, help="envelope radius of every tool head (mm)")
    mm.add_argument("--envelope", action="append", default=[], metavar="N:R",
                    help="envelope radius R (mm) of motion system N's head (repeatable)")
    mm.add_argument("--axis-map", action="append", default=[], metavar="N:X=U,Y=V[,Z=Z]",
                    help="axis letters motion system N drives as its head's X, Y (and Z) (repeatable)")
    mm.add_argument("--home", action="append", default=[], metavar="N:X,Y",
                    help="where motion system N's head is at the start and after homing (repeatable)")
    mm.add_argument("--shared-gantry", action="store_true", default=None,
                    help="the heads share one gantry: check their X order (system 0 leftmost) instead of discs")
    mm.add_argument("--dual-gantry", action="store_true", default=None,
                    help="each head on a gantry of its own over one pair of Y rails: check their Y order "
                         "(system 0 in front) instead of discs")
    mm.add_argument("--perturb", action="append", default=[], metavar="N:FEED,ACCEL",
                    help="time motion system N's moves at FEED times their feed rates and ACCEL times their "
                         "accelerations (e.g. 1:0.8,1 or 1:1,0.5), as a machine that keeps the file's order but "
                         "not its pace would (repeatable)")
    mm.add_argument("--extrusion-tol", type=float, default=0.01,
                    help="relative tolerance of the planned extrusion per tool, default 0.01")
    ap.add_argument("--json", help="JSON report path (default FILE.replay.json; '-' prints it instead of the summary)")
    # Let coordinate lists start with a minus sign: "--bed -100,-100,100,100".
    fixed: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in ("--bed", "--bed-circle", "--place") and i + 1 < len(argv) \
                and re.match(r"^-[\d.]", argv[i + 1]):
            fixed.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
            continue
        fixed.append(argv[i])
        i += 1
    a = ap.parse_args(fixed)
    o = Options()
    o.mesh = a.mesh
    o.place = a.place
    if o.place.lower() not in ("centre", "center", "keep"):
        _floats(o.place, 2, "--place")
    if a.bed:
        o.bed_rect = _floats(a.bed, 4, "--bed")  # type: ignore[assignment]
        x0, y0, x1, y1 = o.bed_rect
        if x1 <= x0 or y1 <= y0:
            raise UsageError("--bed: need X0 < X1 and Y0 < Y1")
    if a.bed_circle:
        o.bed_circle = _floats(a.bed_circle, 3, "--bed-circle")  # type: ignore[assignment]
        if o.bed_circle[2] <= 0:
            raise UsageError("--bed-circle: radius must be positive")
    if a.filament <= 0:
        raise UsageError("--filament must be positive")
    o.filament = a.filament
    o.min_extrude_temp = a.min_extrude_temp
    o.volume_tol = a.volume_tol
    o.coverage_min = a.coverage_min
    o.overlap_max = a.overlap_max
    if a.coverage_every < 1:
        raise UsageError("--coverage-every must be at least 1")
    o.coverage_every = a.coverage_every
    o.bead_ends = a.bead_ends
    o.time_tol = a.time_tol
    o.flavor = a.flavor
    if a.accel:
        vals = [float(v) for v in a.accel.split(",")]
        if not 1 <= len(vals) <= 3 or any(v <= 0 for v in vals):
            raise UsageError("--accel: P[,T[,R]] positive numbers")
        p = vals[0]
        t = vals[1] if len(vals) > 1 else p
        rr = vals[2] if len(vals) > 2 else p
        o.accel = (p, t, rr)
    o.junction_deviation = a.junction_deviation
    _heating_options(a, o)
    if a.head_radius is not None:
        if a.head_radius < 0:
            raise UsageError("--head-radius must not be negative")
        o.head_radius = a.head_radius
    for item in a.envelope:
        n, val = _system_item(item, "--envelope")
        r_env = _floats(val, 1, "--envelope")[0]
        if r_env < 0:
            raise UsageError("--envelope: radius must not be negative")
        o.envelopes[n] = r_env
    for item in a.axis_map:
        n, val = _system_item(item, "--axis-map")
        amap: dict[str, str] = {}
        for part in val.split(","):
            m = re.match(r"^\s*([XYZ])\s*=\s*([A-Za-z])\s*$", part)
            if not m:
                raise UsageError(f"--axis-map: expected N:X=<letter>,Y=<letter>[,Z=<letter>], got {item!r}")
            amap[m.group(1).upper()] = m.group(2).upper()
        o.axis_maps[n] = amap
    for item in a.home:
        n, val = _system_item(item, "--home")
        o.homes[n] = _floats(val, 2, "--home")  # type: ignore[assignment]
    o.shared_gantry = a.shared_gantry
    o.dual_gantry = a.dual_gantry
    for item in a.perturb:
        n, val = _system_item(item, "--perturb")
        scales = _floats(val, 2, "--perturb")
        if not all(0.05 <= v <= 20 for v in scales):
            raise UsageError("--perturb scales must lie in 0.05..20")
        o.perturb[n] = tuple(scales)  # type: ignore[assignment]
    if a.extrusion_tol <= 0:
        raise UsageError("--extrusion-tol must be positive")
    o.extrusion_tol = a.extrusion_tol
    return a.file, o, a.json


def _heating_options(a: argparse.Namespace, o: Options) -> None:
    """The heating model's and tool changes' options, checked."""
    tuning = {"--cooling-rate": a.cooling_rate, "--bed-heating-rate": a.bed_heating_rate,
              "--residency": a.residency, "--bed-residency": a.bed_residency, "--ambient": a.ambient}
    if a.heating_rate is None:
        # Silently ignoring them would hide a command line that lost its --heating-rate.
        given = [k for k, v in tuning.items() if v is not None]
        if given:
            raise UsageError(f"{', '.join(given)} need(s) --heating-rate (the heating model is off without it)")
    for name, v in (("--heating-rate", a.heating_rate), ("--cooling-rate", a.cooling_rate),
                    ("--bed-heating-rate", a.bed_heating_rate)):
        if v is not None and not v > 0:
            raise UsageError(f"{name} must be positive")
    for name, v in (("--residency", a.residency), ("--bed-residency", a.bed_residency),
                    ("--tool-change-time", a.tool_change_time)):
        if v is not None and not v >= 0:
            raise UsageError(f"{name} must not be negative")
    o.heating_rate = a.heating_rate
    if a.cooling_rate is not None:
        o.cooling_rate = a.cooling_rate
    if a.bed_heating_rate is not None:
        o.bed_heating_rate = a.bed_heating_rate
    o.residency = a.residency
    o.bed_residency = a.bed_residency
    if a.ambient is not None:
        o.ambient = a.ambient
    o.tool_change_time = a.tool_change_time


def _system_item(item: str, what: str) -> tuple[int, str]:
    """``N:rest`` of a per-motion-system option."""
    m = re.match(r"^\s*(\d+)\s*:(.*)$", item)
    if not m:
        raise UsageError(f"{what}: expected N:..., got {item!r}")
    return int(m.group(1)), m.group(2)


def main(argv: Iterable[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        path, opts, json_path = parse_args(argv)
    except UsageError as exc:
        print(f"gcode_replay.py: error: {exc}", file=sys.stderr)
        return 2
    except SystemExit as exc:  # argparse
        return int(exc.code) if isinstance(exc.code, int) else 2
    try:
        with open(path, encoding="utf-8", errors="replace") as fh:
            text = fh.read()
    except OSError as exc:
        print(f"gcode_replay.py: error: cannot read {path}: {exc}", file=sys.stderr)
        return 2
    try:
        rep = analyse(text, opts, name=path)
    except ParseError as exc:
        print(f"{path}:{exc.line}: parse error: {exc.message}", file=sys.stderr)
        return 2
    except UsageError as exc:
        print(f"gcode_replay.py: error: {exc}", file=sys.stderr)
        return 2
    doc = json.dumps(rep, indent=1, default=_json_default)
    if json_path == "-":
        print(doc)
    else:
        out = json_path or (os.path.splitext(path)[0] + ".replay.json")
        with open(out, "w", encoding="utf-8") as fh:
            fh.write(doc)
        print(summary(rep))
        print(f"report: {out}")
    return 0 if rep["ok"] else 1


def _json_default(obj):
    if isinstance(obj, (np.floating,)):
        return float(obj)
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    raise TypeError(f"not JSON serialisable: {type(obj)}")


if __name__ == "__main__":
    sys.exit(main())
