"""Multiple motion systems (RepRapFirmware 3.5) for the G-code replay checker.

``gcode_replay.analyse`` hands a file to ``analyse_multi`` when it selects
motion systems with ``M596``. Written from Duet3D's documentation (the
"Multiple motion systems" page of the RepRapFirmware user manual and the
M596, M597, M598, M606 and M400 entries of the G-code dictionary), never from
Lamina's exporter or planner. The semantics used, and where each comes from,
are in README.md ("Multiple motion systems").

The file is split into one command stream per motion system: ``M596 P<n>``
routes the commands that follow (and the ``;TYPE:``/``;LAYER:`` comments) to
stream n; stream 0 until the first M596. Each stream is replayed by its own
``gcode_replay.Replay`` (its own tool, position, feed, E mode and planner), so
every single-stream check (heating, bed, layers, features, volume, coverage)
runs per stream, with heaters and tool definitions shared as on the machine.

Synchronisation points: ``M598``, ``M400`` and ``G4 P0`` are barriers (each
stream stops and waits until all have reached that line); ``M606 S1`` (forking
the job into one reader per motion system) starts the streams together; the
end of the job waits for all. Between barriers each stream's moves are timed with the
checker's look-ahead trapezoid model and G4 dwells; the build time is the
release time of the last barrier. With ``--heating-rate`` the heating waits
are timed by ``gcode_replay.HeatingModel`` (``heating_timeline``): the
prologue before the fork as a single-stream file, then each stream with a copy
of the heaters as the prologue left them, its own targets and its own clock.

Further checks of this mode:

streams      the job is forked (M606 S1) before a second motion system is
             selected; an axis is driven by one motion system at a time
             (axes are released only by M598/M400); a shared axis (e.g. a
             common Z) does not move while another motion system moves
             filament between the same synchronisation points; a stream names
             only the axes it drives; a tool belongs to one motion system.
collisions   the tool heads' envelopes (discs around each head's XY) never
             overlap, or with ``--shared-gantry`` the heads keep their X order
             and distance; exact closest approach of the piecewise
             constant-acceleration motions.
separation   the file's own M597 rule, block-wise as the firmware checks it.
extrusion    PART volume per tool against ``; planned extrusion T<n>: <mm3> mm3``.
time         the replayed build time against ``; estimated printing time``
             (default tolerance 0.02), and the ratio to
             ``; sequential build time: <s> s`` when the file states it.
"""

from __future__ import annotations

import bisect
import heapq
import math
import re
from types import SimpleNamespace

import numpy as np

import gcode_replay as gr

#: RepRapFirmware 3.5 supports two motion systems ("Multiple motion systems").
RRF_MAX_SYSTEMS = 2
#: Letters that name axes in a move (the ones a stream may or may not drive).
AXIS_LETTERS = "XYZUVWABC"
ROLES = "XYZ"
#: Collision episodes kept in the report (the count is exact).
MAX_COLLISIONS = 200
#: Envelopes may touch; they overlap when closer than the radii's sum minus this (mm).
OVERLAP_TOL = 1e-9
#: Commands whose effect is machine-wide configuration: applied to every stream.
BROADCAST = {"M220", "M221", "M302"}
#: Per-axis limits (accelerations, speeds, jerk): machine-wide, but each value is
#: the named axis's own, so a motion system gets the values of its own letters
#: (U and V for a head driven by U and V), and none for a letter left out.
AXIS_SETTINGS = {"M201", "M203", "M205", "M566"}
#: Axis settings that a motion system runs at firmware defaults without.
REQUIRED_AXIS_SETTINGS = ("M201", "M203", "M566")
#: M204 (print and travel accelerations) is per motion system in RepRapFirmware
#: 3.5: it applies to the system selected, and one before the fork to system 0.
PER_SYSTEM = {"M204"}
#: Filament pulled back at least this far (mm) counts as retracted at a barrier.
PULLED_BACK_MIN = 0.2
#: A loaded nozzle standing this long (s) at a barrier oozes nothing that shows: as
#: long as it stands at a sharp corner of any print.
LOADED_WAIT_MIN = 0.2
#: Moves and other commands that carry axis letters (translated per stream).
AXIS_COMMANDS = {"G0", "G1", "G2", "G3", "G28", "G30", "G92"}

_SYSTEM_RE = re.compile(r"^[ \t]*;[ \t]*(?:machine:[ \t]*)?motion system[ \t]+(\d+)[ \t]*:(.*)$",
                        re.IGNORECASE | re.MULTILINE)
_MACHINE_RE = re.compile(r"^[ \t]*;[ \t]*machine:(.*)$", re.IGNORECASE | re.MULTILINE)
_SEQ_RE = re.compile(r"^[ \t]*;.*?sequential build time:\s*([-+]?\d+(?:\.\d*)?)\s*s\b",
                     re.IGNORECASE | re.MULTILINE)
_PLANNED_RE = re.compile(r"^[ \t]*;.*?planned extrusion\s+T(\d+)\s*:\s*([-+]?\d+(?:\.\d*)?)\s*mm3\b",
                         re.IGNORECASE | re.MULTILINE)
_TIME_LINE_RE = re.compile(r"^[ \t]*;.*?estimated printing time:\s*([-+]?\d+(?:\.\d*)?)\s*s\b",
                           re.IGNORECASE | re.MULTILINE)
_M596_P_RE = re.compile(r"^\s*(?:N\d+\s*)?M596\s*P\s*(\d+)", re.IGNORECASE | re.MULTILINE)
_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+))"


def _line_of(text: str, pos: int) -> int:
    return text.count("\n", 0, pos) + 1


# ---------------------------------------------------------------------------
# Shared machine state
# ---------------------------------------------------------------------------

class Ctx:
    """Which stream the command being replayed belongs to."""

    stream: int | None = None


class SharedHeater:
    """A heater of the machine: one target, seen by every stream; a wait
    (M109/M116) counts for the stream that waited, and for the others once a
    barrier has passed (what happened before a barrier happened before every
    stream's next command)."""

    __slots__ = ("target", "_waited", "ctx")

    def __init__(self, ctx: Ctx):
        self.target = 0.0
        self._waited: set = set()
        self.ctx = ctx

    @property
    def waited(self) -> bool:
        return self.ctx.stream in self._waited

    @waited.setter
    def waited(self, value: bool) -> None:
        if value:
            self._waited.add(self.ctx.stream)
        else:
            self._waited.clear()

    def set_target(self, value: float) -> None:
        if value > self.target + 1e-9:
            self._waited.clear()
        self.target = value

    def release(self, streams) -> None:
        if self._waited:
            self._waited.update(streams)


class SharedCheck(gr.Check):
    """A check shared by the streams; messages name the motion system."""

    def __init__(self, name: str, description: str, ctx: Ctx):
        super().__init__(name, description)
        self.ctx = ctx

    def fail(self, line: int | None, message: str) -> None:
        if self.ctx.stream is not None:
            message = f"system {self.ctx.stream}: {message}"
        super().fail(line, message)


class StreamReplay(gr.Replay):
    """One motion system's command stream: a Replay with shared heaters, tools
    and checks, layers sampled by number (so that the streams' layers line up
    for the coverage check), and PART volume per tool."""

    def __init__(self, opts: gr.Options, system: int, mm: "MultiReplay"):
        super().__init__(opts)
        self.system = system
        self.mm = mm
        self.checks = mm.checks
        self.tools = mm.tools
        self.heaters = mm.heaters
        self.events: list[tuple] = []
        self.dwell_logged = 0.0  # self.dwell already in self.events
        self.part_by_tool: dict[int, float] = {}
        self.commands = 0

    def heater(self, key: int):
        h = self.heaters.get(key)
        if h is None:
            h = self.heaters[key] = SharedHeater(self.mm.ctx)
        return h

    def log_dwell(self) -> None:
        """The dwell (G4, tool change) added since the last entry, as an event."""
        if self.dwell > self.dwell_logged:
            m = self.machine()
            self.events.append(("d", self.dwell - self.dwell_logged, m[0], m[1], self.line))
        self.dwell_logged = self.dwell

    def set_target(self, key, value: float) -> None:
        super().set_target(key, value)
        self.log_heat()

    def heat_wait(self, keys, rule: gr.WaitRule) -> None:
        super().heat_wait(keys, rule)
        self.log_heat()

    def log_heat(self) -> None:
        """A heating-model entry (``heat_events``) at its place among the
        stream's moves, dwells and barriers (a tool change's dwell comes before
        the heaters' switch-over)."""
        if self.heat_on:
            self.log_dwell()
            m = self.machine()
            self.events.append(("h", len(self.heat_events) - 1, m[0], m[1], self.line))

    def start_layer(self, number: int) -> None:
        super().start_layer(number)
        self.mm.layer_marks.append((self.mm.line, number))
        every = max(1, self.o.coverage_every)
        self.layer.sampled = self.o.mesh is not None and number % every == 0

    def account_deposit(self, deposit: float, line: int, old, new, xy_len: float) -> None:
        super().account_deposit(deposit, line, old, new, xy_len)
        if self.feature == "PART":
            vol = deposit * self.area if not self.volumetric else deposit
            tool = self.active_tool()
            key = -1 if tool is None else tool
            self.part_by_tool[key] = self.part_by_tool.get(key, 0.0) + vol

    def select_tool(self, n: int) -> None:
        if n >= 0:
            for other in self.mm.streams:
                if other is not self and other.current == n:
                    self.mm.checks["streams"].fail(
                        self.line, f"T{n} selected while motion system {other.system} holds it "
                                   f"(each motion system has its own current tool)")
        super().select_tool(n)

    def machine(self) -> list[float | None]:
        return [None if p is None else p + o for p, o in zip(self.pos, self.offset)]


# ---------------------------------------------------------------------------
# Machine configuration: options and the file's header
# ---------------------------------------------------------------------------

def parse_header(text: str) -> tuple[dict[int, dict], bool | None, list[str]]:
    """``; motion system <n>: X axis U, Y axis Y[, Z axis Z], envelope 5.0 mm[, home X 0 Y 0]``
    lines and ``; machine: shared gantry``. Returns (systems, shared gantry, warnings)."""
    systems: dict[int, dict] = {}
    warnings: list[str] = []
    for m in _SYSTEM_RE.finditer(text):
        n = int(m.group(1))
        line = _line_of(text, m.start())
        cfg = systems.setdefault(n, {"axes": {}, "radius": None, "home": None, "line": line})
        for clause in m.group(2).split(","):
            c = clause.strip()
            if not c:
                continue
            a = re.fullmatch(r"([XYZ])\s+axis\s+([A-Za-z])", c, re.IGNORECASE)
            if a:
                cfg["axes"][a.group(1).upper()] = a.group(2).upper()
                continue
            e = re.fullmatch(r"envelope\s+" + _NUM + r"\s*(?:mm)?", c, re.IGNORECASE)
            if e:
                cfg["radius"] = float(e.group(1))
                continue
            h = re.fullmatch(r"home\s+X\s*" + _NUM + r"\s+Y\s*" + _NUM, c, re.IGNORECASE)
            if h:
                cfg["home"] = (float(h.group(1)), float(h.group(2)))
                continue
            warnings.append(f"line {line}: motion system clause {c!r} not understood")
    gantry = None
    for m in _MACHINE_RE.finditer(text):
        body = m.group(1).lower()
        if "motion system" in body:
            continue
        if "shared gantry" in body:
            gantry = True
        elif "dual gantry" in body:
            gantry = "dual"
    return systems, gantry, warnings


class System:
    """A motion system's configuration: which axis letters move its head's X,
    Y and Z, its envelope radius, where its head is after homing."""

    def __init__(self, number: int):
        self.number = number
        self.axes = {"X": "X", "Y": "Y", "Z": "Z"}
        self.radius: float | None = None
        self.home: tuple[float, float] | None = None
        self.source = {"axes": "default", "radius": None, "home": None}

    def to_json(self) -> dict:
        return {"system": self.number, "axes": dict(self.axes), "envelope_mm": self.radius,
                "home": list(self.home) if self.home else None, "from": dict(self.source)}


# ---------------------------------------------------------------------------
# The replay of all streams
# ---------------------------------------------------------------------------

class MultiReplay:
    """Splits a job file into its motion systems' streams and replays them."""

    def __init__(self, opts: gr.Options, text: str):
        self.o = opts
        self.ctx = Ctx()
        names = [
            ("parse", "every line is read; unknown commands are listed"),
            ("streams", "the job forks, and axes and tools belong to one motion system at a time"),
            ("features", "extrusion is preceded by a ;TYPE: marker"),
            ("layers", "per stream: layer Z never decreases; extrusion happens at the layer Z"),
            ("heating", "filament moves only with a selected, hot, waited-for tool"),
            ("bed", "every move stays inside the bed"),
            ("mixes", "every mix sums to 1 within 0.011"),
            ("volume", "PART volume matches the mesh volume"),
            ("coverage", "PART beads cover each sampled layer's cross-section without overlap"),
            ("time", "replayed build time matches the file's estimate"),
            ("extrusion", "PART volume per tool matches the planned volume"),
            ("collisions", "the tool heads' envelopes never overlap"),
            ("separation", "the file's M597 axis separation holds in every block between synchronisation points"),
        ]
        names += [
            ("settings", "every moving motion system gets its own M204 and axis limits naming its own axes"),
            ("end", "the job ends with every heater off"),
            ("waits", "no motion system waits at a synchronisation point with its nozzle loaded (filament not "
                      "pulled back)"),
        ]
        self.checks = {k: SharedCheck(k, d, self.ctx) for k, d in names}
        self.axis_settings_used: set[str] = set()
        self.axis_settings: dict[int, set] = {}
        self.per_system_set: dict[int, set] = {}
        # Per barrier index: the streams that reached it with a loaded nozzle.
        self.loaded_at: dict[int, list[int]] = {}
        self.extruded_tools: dict[int, set] = {}
        self.tools: dict[int, gr.Tool] = {}
        self.heaters: dict[int, SharedHeater] = {}
        self.warnings: list[str] = []
        self.line = 0
        # (line, layer number) of every ;LAYER: comment, in file order.
        self.layer_marks: list[tuple[int, int]] = []
        self.cur = 0
        self.forked = False
        # Index in self.barriers of the fork (M606 S1): the heating model's
        # prologue ends there.
        self.fork_barrier: int | None = None
        self.warned_unforked = False
        self.barriers: list[dict] = []
        self.configure(text)
        probe = gr.Replay(opts)
        probe.prescan(text)
        self.flavor_from = probe.flavor_from
        if probe.flavor != "rrf":
            self.warnings.append("multiple motion systems (M596) are a RepRapFirmware 3.5 feature: "
                                 f"replayed as RepRapFirmware (the flavour was {probe.flavor}, {probe.flavor_from})")
            self.flavor_from = "M596 (multiple motion systems)"
        self.mixing = probe.mixing
        self.streams: list[StreamReplay] = []
        for n in range(len(self.systems)):
            st = StreamReplay(opts, n, self)
            st.flavor = "rrf"
            st.flavor_from = self.flavor_from
            st.mixing = probe.mixing
            st.uses_t = probe.uses_t
            home = self.systems[n].home
            if home is not None:
                st.pos[0], st.pos[1] = home
            self.streams.append(st)
        # axis letters: per stream letter -> role; which letters several systems drive
        self.trans = [{L: role for role, L in s.axes.items()} for s in self.systems]
        drivers: dict[str, set[int]] = {}
        for s in self.systems:
            for L in s.axes.values():
                drivers.setdefault(L, set()).add(s.number)
        self.drivers = drivers
        self.shared_letters = {L for L, who in drivers.items() if len(who) > 1}
        # physical axis positions (machine coordinates) and who moved them last
        self.phys: dict[str, float | None] = {}
        self.last_mover: dict[str, int] = {}
        for s, st in zip(self.systems, self.streams):
            for i, role in enumerate(ROLES):
                if st.pos[i] is not None:
                    self.phys[s.axes[role]] = st.pos[i]
                    self.last_mover[s.axes[role]] = s.number
        # epochs: ownership (until M598/M400 release), synchronisation (until any barrier)
        self.owner: dict[str, tuple[int, int]] = {}
        self.owner_reported: set = set()
        self.moved: dict[str, dict[int, int]] = {}
        self.extruded: dict[int, int] = {}
        self.separation: list[dict] = []
        self.sep_state: list[dict] = []
        # Each reader has its own M82/M83 flag; a forked reader's is config.g's,
        # which the checker does not know: streams other than 0 must set theirs.
        self.e_mode_set = [s == 0 for s in range(len(self.streams))]
        self.e_mode_reported: set = set()

    # -- configuration ---------------------------------------------------------

    def configure(self, text: str) -> None:
        o = self.o
        header, gantry, warns = parse_header(text)
        self.warnings.extend(warns)
        referenced = {int(m.group(1)) for m in _M596_P_RE.finditer(text)}
        count = max([0] + list(referenced) + list(header) + list(o.axis_maps) + list(o.envelopes) + list(o.homes)) + 1
        self.systems = [System(n) for n in range(count)]
        for n, cfg in header.items():
            s = self.systems[n]
            if cfg["axes"]:
                s.axes.update(cfg["axes"])
                s.source["axes"] = f"header (line {cfg['line']})"
            if cfg["radius"] is not None:
                s.radius = cfg["radius"]
                s.source["radius"] = f"header (line {cfg['line']})"
            if cfg["home"] is not None:
                s.home = cfg["home"]
                s.source["home"] = f"header (line {cfg['line']})"
        for s in self.systems:
            if o.head_radius is not None:
                s.radius = o.head_radius
                s.source["radius"] = "option --head-radius"
            if s.number in o.envelopes:
                s.radius = o.envelopes[s.number]
                s.source["radius"] = "option --envelope"
            if s.number in o.axis_maps:
                s.axes.update(o.axis_maps[s.number])
                s.source["axes"] = "option --axis-map"
            if s.number in o.homes:
                s.home = tuple(o.homes[s.number])
                s.source["home"] = "option --home"
            if s.number > 0 and s.source["axes"] == "default":
                self.warnings.append(f"no axis map for motion system {s.number}: assuming it drives X, Y and Z")
        self.shared_gantry = bool(o.shared_gantry if o.shared_gantry is not None else gantry is True)
        self.shared_gantry_from = ("option --shared-gantry" if o.shared_gantry else
                                   "header" if gantry is True else None)
        self.dual_gantry = bool(o.dual_gantry if o.dual_gantry is not None else gantry == "dual")
        self.sequential = None
        for m in _SEQ_RE.finditer(text):
            self.sequential = (float(m.group(1)), _line_of(text, m.start()))
        self.estimated = None
        for m in _TIME_LINE_RE.finditer(text):
            self.estimated = (float(m.group(1)), _line_of(text, m.start()))
        self.planned: dict[int, tuple[float, int]] = {}
        for m in _PLANNED_RE.finditer(text):
            self.planned[int(m.group(1))] = (float(m.group(2)), _line_of(text, m.start()))

    # -- main loop ---------------------------------------------------------------

    def run(self, text: str) -> None:
        for lineno, kind, cmd, params in gr.statements(text):
            self.line = lineno
            if kind is gr.MOVE:
                self.move(self.cur, cmd, params)
            elif kind is gr.COMMENT:
                st = self.enter(self.cur)
                st.comment(params)
            else:
                # COMMAND, and MOVE_WORDS: a move whose words need the tokenizer
                # goes through the command dispatch.
                self.command(cmd, params)
        self.barrier("end", release=True)
        for st in self.streams:
            st.finish()
        self.ctx.stream = None

    def enter(self, s: int) -> StreamReplay:
        st = self.streams[s]
        st.line = self.line
        self.ctx.stream = s
        return st

    def translate(self, s: int, params: dict) -> dict:
        """A stream's axis letters to its head's roles (U -> X for a system
        whose X axis is U); letters of axes it does not drive are dropped and
        reported."""
        tr = self.trans[s]
        out = {}
        for k, v in params.items():
            role = tr.get(k)
            if role is not None:
                out[role] = v
            elif k in AXIS_LETTERS:
                self.checks["streams"].fail(
                    self.line, f"names axis {k}, which it does not drive (its axes: "
                               + ", ".join(f"{r}={L}" for r, L in self.systems[s].axes.items()) + ")")
            else:
                out[k] = v
        return out

    def take_axes(self, s: int, letters) -> None:
        """A motion system that names an axis in a move owns it until a
        release (M598, M400)."""
        for L in letters:
            own = self.owner.get(L)
            if own is None:
                self.owner[L] = (s, self.line)
            elif own[0] != s:
                key = (L, own[0], s)
                if key not in self.owner_reported:
                    self.owner_reported.add(key)
                    self.checks["streams"].fail(
                        self.line, f"moves axis {L}, owned by motion system {own[0]} since line {own[1]} "
                                   f"(an axis belongs to one motion system until M598 or M400 releases it)")

    def move(self, s: int, cmd: str, params: dict) -> None:
        st = self.enter(s)
        st.commands += 1
        params = self.translate(s, params)
        axes = self.systems[s].axes
        self.take_axes(s, [axes[r] for r in ROLES if params.get(r) is not None])
        before = st.machine()
        e0, n0 = st.e, len(st.moves)
        st.do_move(cmd, params)
        self.after(s, st, before, e0, n0, moved=True)

    def run_on(self, s: int, cmd: str, raw: dict) -> None:
        st = self.enter(s)
        st.commands += 1
        if cmd in AXIS_COMMANDS:
            raw = self.translate(s, raw)
            axes = self.systems[s].axes
            if cmd in ("G0", "G1", "G2", "G3"):
                self.take_axes(s, [axes[r] for r in ROLES if raw.get(r) is not None])
            elif cmd in ("G28", "G30"):
                named = [axes[r] for r in ROLES if r in raw]
                self.take_axes(s, named or list(axes.values()))
        before = st.machine()
        e0, n0 = st.e, len(st.moves)
        st.command(cmd, raw)
        if cmd == "G28" and self.systems[s].home is not None:
            homed = [r for r in ROLES if r in raw] or list(ROLES)
            for i, r in enumerate("XY"):
                if r in homed:
                    st.pos[i] = self.systems[s].home[i]
        self.after(s, st, before, e0, n0, moved=cmd in ("G0", "G1", "G2", "G3"))
        for other in self.streams:
            other.ready_cache = None

    def after(self, s: int, st: StreamReplay, before, e0: float, n0: int, moved: bool) -> None:
        """Records what the command did to the stream's timeline, the physical
        axes and the current synchronisation epoch."""
        now = st.machine()
        line = self.line
        n1 = len(st.moves)
        if n1 > n0:
            st.events.append(("m", n0, before[0], before[1], now[0], now[1], line))
            for k in range(n0 + 1, n1):  # never more than one move per command today
                st.events.append(("m", k, now[0], now[1], now[0], now[1], line))
        st.log_dwell()
        axes = self.systems[s].axes
        for i, role in enumerate(ROLES):
            L = axes[role]
            a, b = before[i], now[i]
            if a == b:
                continue
            if a is not None and b is not None and abs(a - b) <= 1e-9:
                continue
            self.phys[L] = b
            self.last_mover[L] = s
            if moved and b is not None:
                self.moved.setdefault(L, {}).setdefault(s, line)
                self.update_separation(L, b)
        if moved and st.e > e0 + 1e-12 and st.active_tool() is not None:
            self.extruded_tools.setdefault(s, set()).add(st.active_tool())
        if moved and st.e != e0:
            self.extruded.setdefault(s, line)
            if not self.e_mode_set[s] and s not in self.e_mode_reported:
                self.e_mode_reported.add(s)
                self.checks["streams"].fail(
                    line, "moves filament before setting its extrusion mode (M82/M83): each reader of a forked "
                          "job has its own mode, which starts as config.g left it (replayed as M82, absolute)")

    def command(self, cmd: str, raw: dict) -> None:
        if cmd == "M596":
            if raw.get("P") is None:
                return
            n = int(gr._number(raw["P"], self.line, "P"))
            self.ctx.stream = None
            if n >= RRF_MAX_SYSTEMS:
                self.checks["streams"].fail(self.line, f"M596 P{n}: RepRapFirmware 3.5 runs two motion systems (0 and 1)")
            if n >= 1 and not self.forked and not self.warned_unforked:
                self.warned_unforked = True
                self.checks["streams"].fail(
                    self.line, f"M596 P{n} before M606 S1: the job is not forked, so one reader executes both "
                               "motion systems' commands and their motion is concurrent only within the movement "
                               "queue (the replay assumes forked streams)")
            self.cur = n
            return
        if cmd == "M606":
            s = raw.get("S")
            if s is not None and gr._number(s, self.line, "S") == 1 and not self.forked:
                self.forked = True
                self.fork_barrier = len(self.barriers)
                self.barrier("M606", release=False)
            return
        if cmd == "M598":
            self.barrier("M598", release=True)
            return
        if cmd == "M400":
            s = raw.get("S")
            keep = s is not None and gr._number(s, self.line, "S") == 1
            self.barrier("M400 S1" if keep else "M400", release=not keep)
            return
        if cmd == "G4":
            p = self.streams[self.cur].floats(raw) if raw else {}
            if not (p.get("S") or p.get("P")):
                # "M400 S1 or G4 P0": wait until all motion stops, keep the axes
                self.barrier("G4 P0", release=False)
                return
        if cmd in ("M0", "M1", "M2"):
            self.barrier(cmd, release=True)
            self.cur = 0
            return
        if cmd == "M597":
            self.set_separation(raw)
            return
        if cmd in BROADCAST:
            for s in range(len(self.streams)):
                self.run_on(s, cmd, raw)
            return
        if cmd in AXIS_SETTINGS:
            self.axis_settings_used.add(cmd)
            for s in range(len(self.streams)):
                own = {k: v for k, v in raw.items() if k not in AXIS_LETTERS}
                for role, letter in self.systems[s].axes.items():
                    if raw.get(letter) is not None:
                        own[role] = raw[letter]
                        self.axis_settings.setdefault(s, set()).add((cmd, letter))
                self.run_on(s, cmd, own)
            return
        if cmd in PER_SYSTEM:
            self.per_system_set.setdefault(self.cur, set()).add(cmd)
        target = self.cur
        if cmd in ("M82", "M83"):
            self.e_mode_set[target] = True
        tool = None
        if cmd in ("G10", "M568") and raw.get("P") is not None and "L" not in raw:
            tool = int(gr._first(raw["P"], self.line, "P"))
        elif cmd == "M104" and raw.get("T") is not None:
            tool = int(gr._first(raw["T"], self.line, "T"))
        if tool is not None:
            # A tool's temperatures are the tool's: the motion system holding it applies them.
            for st in self.streams:
                if st.current == tool:
                    target = st.system
        self.run_on(target, cmd, raw)

    # -- synchronisation ---------------------------------------------------------

    def barrier(self, kind: str, release: bool) -> None:
        """Every stream stops and waits here until all have arrived."""
        self.ctx.stream = None
        self.close_epoch()
        idx = len(self.barriers)
        for s, st in enumerate(self.streams):
            st.sync()
            st.in_run = False
            m = st.machine()
            st.events.append(("b", idx, m[0], m[1], self.line))
            if self.forked and kind == "M598" and self.loaded(st):
                self.loaded_at.setdefault(idx, []).append(s)
        everyone = range(len(self.streams))
        for h in self.heaters.values():
            h.release(everyone)
        for s, st in enumerate(self.streams):
            st.ready_cache = None
            for i, role in enumerate(ROLES):
                L = self.systems[s].axes[role]
                if L in self.phys and self.last_mover.get(L, s) != s:
                    v = self.phys[L]
                    st.pos[i] = None if v is None else v - st.offset[i]
        if release:
            self.owner.clear()
            self.owner_reported.clear()
        self.barriers.append({"kind": kind, "line": self.line})
        self.open_separation_blocks()

    def loaded(self, st) -> bool:
        """Whether a stream's nozzle is hot with filament pushed to its tip: it has
        extruded with its tool, and not pulled back since."""
        tool = st.active_tool()
        if tool is None or tool not in self.extruded_tools.get(st.system, set()):
            return False
        keys = st.tool_heaters(tool)
        if not keys or self.heaters.get(keys[0]) is None or self.heaters[keys[0]].target <= 0:
            return False
        return st.retracted.get(keys[0], 0.0) < PULLED_BACK_MIN

    def close_epoch(self) -> None:
        """A shared axis (several systems drive it, e.g. one Z) must not move
        while another of its systems moves filament between the same
        synchronisation points."""
        for L in sorted(self.shared_letters):
            for a, line_a in sorted(self.moved.get(L, {}).items()):
                for b in sorted(self.drivers[L]):
                    if b != a and b in self.extruded:
                        self.checks["streams"].fail(
                            line_a, f"motion system {a} moves shared axis {L} (line {line_a}) between the same "
                                    f"synchronisation points as motion system {b} moves filament (line "
                                    f"{self.extruded[b]}): put an M598 between them")
        self.moved = {}
        self.extruded = {}

    def set_separation(self, raw: dict) -> None:
        vals = []
        for k, v in raw.items():
            if k in AXIS_LETTERS and v is not None:
                vals.append((k, gr._number(v.split(":")[0], self.line, k)))
        if len(vals) != 2 or vals[0][1] == vals[1][1]:
            self.warnings.append(f"line {self.line}: M597 needs two axes with different values; ignored")
            return
        (la, va), (lb, vb) = sorted(vals, key=lambda t: t[1])
        rule = {"low": la, "high": lb, "distance": vb - va, "line": self.line}
        self.separation.append(rule)
        self.sep_state.append({})
        self.open_separation_blocks()

    def open_separation_blocks(self) -> None:
        for k, rule in enumerate(self.separation):
            lo = self.phys.get(rule["low"])
            hi = self.phys.get(rule["high"])
            self.sep_state[k] = {"max_low": -math.inf if lo is None else lo,
                                 "min_high": math.inf if hi is None else hi, "reported": False}

    def update_separation(self, letter: str, value: float) -> None:
        for k, rule in enumerate(self.separation):
            st = self.sep_state[k]
            if letter == rule["low"]:
                st["max_low"] = max(st["max_low"], value)
            elif letter == rule["high"]:
                st["min_high"] = min(st["min_high"], value)
            else:
                continue
            if not st["reported"] and st["min_high"] - st["max_low"] < rule["distance"] - 1e-9:
                st["reported"] = True
                self.checks["separation"].fail(
                    self.line, f"M597 (line {rule['line']}): in this block {rule['high']} reaches "
                               f"{st['min_high']:.3f} and {rule['low']} {st['max_low']:.3f}, less than "
                               f"{rule['distance']:g} mm apart; the firmware aborts the job before this move")


# ---------------------------------------------------------------------------
# Timeline: when each head is where
# ---------------------------------------------------------------------------

class Track:
    """One head's motion as contiguous pieces covering [0, build time]: a
    move (constant acceleration in each of its three phases), a dwell, or a
    wait at a barrier. Arrays, one entry per piece."""

    FIELDS = ("t0", "t1", "x0", "y0", "ux", "uy", "L", "v0", "vp", "ta", "tc", "td", "a", "line", "kind")

    def __init__(self):
        self.rows: list[tuple] = []

    def add(self, t0, t1, x0, y0, x1, y1, length=0.0, ph=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), a=0.0, line=0, kind=0):
        nan = math.nan
        if x0 is None or y0 is None or x1 is None or y1 is None:
            x0 = y0 = nan
            ux = uy = 0.0
        elif length > 0:
            ux = (x1 - x0) / length
            uy = (y1 - y0) / length
        else:
            ux = uy = 0.0
        v0, vp, _v1, ta, tc, td = ph
        self.rows.append((t0, t1, x0, y0, ux, uy, length, v0, vp, ta, tc, td, a, line, kind))

    def freeze(self) -> None:
        arr = np.array(self.rows, dtype=float).reshape(-1, len(self.FIELDS))
        for i, f in enumerate(self.FIELDS):
            setattr(self, f, arr[:, i])
        self.n = len(arr)

    def distance(self, k: np.ndarray, t: np.ndarray) -> np.ndarray:
        """Path distance covered by piece k at absolute time t (vectorised)."""
        tau = np.clip(t - self.t0[k], 0.0, None)
        ta, tc, td = self.ta[k], self.tc[k], self.td[k]
        v0, vp, a = self.v0[k], self.vp[k], self.a[k]
        da = v0 * ta + 0.5 * a * ta * ta
        dc = vp * tc
        t1 = np.minimum(tau, ta)
        s = v0 * t1 + 0.5 * a * t1 * t1
        t2 = np.clip(tau - ta, 0.0, tc)
        s = np.where(tau > ta, da + vp * t2, s)
        t3 = np.clip(tau - ta - tc, 0.0, td)
        s = np.where(tau > ta + tc, da + dc + vp * t3 - 0.5 * a * t3 * t3, s)
        return np.clip(s, 0.0, self.L[k])

    def xy(self, k: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s = self.distance(k, t)
        return self.x0[k] + self.ux[k] * s, self.y0[k] + self.uy[k] * s

    def state(self, k: int, t: float, tmid: float) -> tuple[float, float, float, float, float, float]:
        """(x, y, vx, vy, ax, ay) of piece k at time t, in the phase that
        contains tmid."""
        t0 = self.t0[k]
        ta, tc = self.ta[k], self.tc[k]
        v0, vp, a = self.v0[k], self.vp[k], self.a[k]
        tau = t - t0
        taum = tmid - t0
        if taum <= ta:
            s = v0 * tau + 0.5 * a * tau * tau
            v, acc = v0 + a * tau, a
        elif taum <= ta + tc:
            s = v0 * ta + 0.5 * a * ta * ta + vp * (tau - ta)
            v, acc = vp, 0.0
        else:
            t3 = tau - ta - tc
            s = v0 * ta + 0.5 * a * ta * ta + vp * tc + vp * t3 - 0.5 * a * t3 * t3
            v, acc = vp - a * t3, -a
        ux, uy = self.ux[k], self.uy[k]
        return (self.x0[k] + ux * s, self.y0[k] + uy * s, ux * v, uy * v, ux * acc, uy * acc)

    def phase_times(self, k: int) -> tuple[float, float]:
        t0 = self.t0[k]
        return t0 + self.ta[k], t0 + self.ta[k] + self.tc[k]


def heating_timeline(mm: MultiReplay, timed: list) -> dict:
    """Times the streams' heating waits with ``gr.HeatingModel`` (the rules of
    a single-stream file).

    The streams are run barrier to barrier, every stream starting a block at
    the release of the previous barrier; within a block the streams' heating
    entries (target changes and waits, ``"h"`` events) are taken in time
    order, each at its stream's clock: the block's start plus the stream's
    moves, dwells and waits before it. Up to the fork (M606 S1) the heaters
    are one model (in practice only stream 0 reads the prologue), so the
    prologue is timed as a single-stream file; at the fork each stream gets a
    copy of it and from then on sees only its own commands' targets (a heater
    belongs to the tool its stream selects). A heater that two streams touch
    after the fork is not modelled beyond that: a warning names it.

    Returns ``waits`` (per stream: event index -> seconds), ``listed`` (each
    wait that took time: system, line, time_s, wait_s) and ``total_s``."""
    streams = mm.streams
    n = len(streams)
    fork = mm.fork_barrier
    shared = gr.HeatingModel(mm.o)
    models = [shared] * n
    cur = [0] * n
    clock = [0.0] * n
    waits: list[dict[int, float]] = [{} for _ in streams]
    listed: list[dict] = []
    touched: dict = {}
    start = 0.0

    def advance(s: int) -> float:
        """Moves stream s to its next heating entry or barrier; its clock there."""
        ev = streams[s].events
        phases = timed[s][0]
        i, t = cur[s], clock[s]
        while ev[i][0] not in ("h", "b"):
            e = ev[i]
            t += phases[e[1]][1] if e[0] == "m" else e[1]
            i += 1
        cur[s], clock[s] = i, t
        return t

    for k in range(len(mm.barriers)):
        after_fork = fork is not None and k > fork
        clock = [start] * n
        heap = [(advance(s), s) for s in range(n)]
        heapq.heapify(heap)
        arrive = [start] * n
        while heap:
            t, s = heapq.heappop(heap)
            st = streams[s]
            i = cur[s]
            e = st.events[i]
            cur[s] = i + 1
            if e[0] == "b":
                arrive[s] = t
                continue
            he = st.heat_events[e[1]]
            if after_fork:
                for key in ([he[3]] if he[0] == "set" else he[4]):
                    touched.setdefault(key, {}).setdefault(s, e[4])
            w = models[s].apply(t, he)
            if w > 0.0:
                waits[s][i] = w
                listed.append({"system": s, "line": he[3], "time_s": t, "wait_s": w})
            clock[s] = t + w
            heapq.heappush(heap, (advance(s), s))
        start = max(arrive, default=start)
        if k == fork:
            models = [shared.copy() for _ in streams]
    for key, who in sorted(touched.items(), key=lambda kv: str(kv[0])):
        if len(who) > 1:
            name = "the bed" if key == gr.BED else f"heater {key}"
            by = " and ".join(f"motion system {s} (line {line})" for s, line in sorted(who.items()))
            mm.warnings.append(f"{name} is set or waited for by {by} after the fork: not modelled (each stream's "
                               "waits see only the targets its own commands set, on its own clock)")
    return {"waits": waits, "listed": listed, "total_s": sum(w["wait_s"] for w in listed)}


def build_timeline(mm: MultiReplay) -> dict:
    """Times every stream's moves, dwells, heating waits and barrier waits;
    returns the build time, barrier release times, per-stream figures and
    head tracks."""
    streams = mm.streams
    nb = len(mm.barriers)
    timed = []
    seg = [[0.0] * nb for _ in streams]
    # The same, of printing moves only.
    seg_print = [[0.0] * nb for _ in streams]
    for s, st in enumerate(streams):
        moves = st.moves
        feed, accel = mm.o.perturb.get(s, (1.0, 1.0))
        if (feed, accel) != (1.0, 1.0):
            moves = [(m[0], m[1] * feed, m[2] * accel) + tuple(m[3:]) for m in moves]
        vin, vout = gr.plan_speeds(moves, st.jd, st.jerk)
        phases = []
        kinds = {"print": 0.0, "travel": 0.0, "e_only": 0.0}
        for i, m in enumerate(moves):
            ph = gr.trapezoid_phases(m[0], vin[i], vout[i], m[1], m[2])
            dur = ph[3] + ph[4] + ph[5]
            phases.append((ph, dur))
            kinds["e_only" if m[6] != 0.0 else ("print" if m[10] != 0.0 else "travel")] += dur
        timed.append((phases, kinds))
    heat = heating_timeline(mm, timed) if streams and streams[0].heat_on else None
    for s, st in enumerate(streams):
        phases = timed[s][0]
        heat_waits = heat["waits"][s] if heat else {}
        k = 0
        for i, ev in enumerate(st.events):
            if ev[0] == "m":
                seg[s][k] += phases[ev[1]][1]
                m = st.moves[ev[1]]
                if m[6] == 0.0 and m[10] != 0.0:
                    seg_print[s][k] += phases[ev[1]][1]
            elif ev[0] == "d":
                seg[s][k] += ev[1]
            elif ev[0] == "h":
                seg[s][k] += heat_waits.get(i, 0.0)
            else:
                k += 1
    release = []
    t = 0.0
    for k in range(nb):
        t = max(t + seg[s][k] for s in range(len(streams))) if streams else t
        release.append(t)
    build = release[-1] if release else 0.0
    # Per layer, the work of its busiest stream: what a layer takes at least when its
    # streams run these moves side by side with no wait. The work before barrier k
    # belongs to the layer of the last ;LAYER: line before it (the layer changes
    # between barriers).
    marks = mm.layer_marks
    mark_lines = [m[0] for m in marks]
    # Of printing moves alone (no travel, retraction or dwell), the same sum is what
    # no order of the same deposits at their feeds can beat.
    per_layer: dict[int, list[float]] = {}
    per_layer_print: dict[int, list[float]] = {}
    for k, b in enumerate(mm.barriers):
        q = bisect.bisect_left(mark_lines, b["line"])
        layer = marks[q - 1][1] if q > 0 else -1
        row = per_layer.setdefault(layer, [0.0] * len(streams))
        row_print = per_layer_print.setdefault(layer, [0.0] * len(streams))
        for s in range(len(streams)):
            row[s] += seg[s][k]
            row_print[s] += seg_print[s][k]
    busiest = sum(max(row, default=0.0) for row in per_layer.values())
    busiest_print = sum(max(row, default=0.0) for row in per_layer_print.values())
    per_stream = []
    tracks = []
    for s, st in enumerate(streams):
        phases, kinds = timed[s]
        heat_waits = heat["waits"][s] if heat else {}
        tr = Track()
        t = 0.0
        busy = wait = dwell = heating = 0.0
        loaded_wait = 0.0
        loaded_waits = []
        last_active = 0.0
        waits = []
        for i, ev in enumerate(st.events):
            if ev[0] == "m":
                m = st.moves[ev[1]]
                ph, dur = phases[ev[1]]
                a = m[2] if (m[2] > 0 and math.isfinite(m[2])) else 0.0
                tr.add(t, t + dur, ev[2], ev[3], ev[4], ev[5], m[0], ph, a, ev[6], 0)
                t += dur
                busy += dur
                last_active = t
            elif ev[0] == "d":
                tr.add(t, t + ev[1], ev[2], ev[3], ev[2], ev[3], line=ev[4], kind=1)
                t += ev[1]
                busy += ev[1]
                dwell += ev[1]
                last_active = t
            elif ev[0] == "h":
                w = heat_waits.get(i, 0.0)
                if w > 0.0:
                    # a heating wait: the head stands still
                    tr.add(t, t + w, ev[2], ev[3], ev[2], ev[3], line=ev[4], kind=3)
                    t += w
                    busy += w
                    heating += w
                    last_active = t
            else:
                r = release[ev[1]]
                w = max(0.0, r - t)
                tr.add(t, t + w, ev[2], ev[3], ev[2], ev[3], line=ev[4], kind=2)
                wait += w
                waits.append(w)
                if w > LOADED_WAIT_MIN and s in mm.loaded_at.get(ev[1], ()):
                    loaded_wait += w
                    loaded_waits.append((w, ev[4]))
                t = t + w
        if not tr.rows:
            tr.add(0.0, build, None, None, None, None, kind=2)
        tr.freeze()
        tracks.append(tr)
        per_stream.append({"busy_s": busy, "wait_s": wait, "dwell_s": dwell, "heating_wait_s": heating,
                           "by_kind_s": kinds, "end_s": last_active, "waits": waits,
                           "loaded_wait_s": loaded_wait, "loaded_waits": loaded_waits})
    return {"build_s": build, "release": release, "streams": per_stream, "tracks": tracks,
            "layers_busiest_s": busiest, "layers_busiest_print_s": busiest_print,
            "heating_wait_s": heat["total_s"] if heat else 0.0, "heating_waits": heat["listed"] if heat else []}


# ---------------------------------------------------------------------------
# Collisions: exact closest approach of two heads
# ---------------------------------------------------------------------------

def _segment_distance(ax0, ay0, ax1, ay1, bx0, by0, bx1, by1):
    """Distance between segments A and B (vectorised, 2D)."""
    def point_seg(px, py, sx0, sy0, sx1, sy1):
        dx, dy = sx1 - sx0, sy1 - sy0
        ll = dx * dx + dy * dy
        with np.errstate(invalid="ignore", divide="ignore"):
            u = np.where(ll > 0, ((px - sx0) * dx + (py - sy0) * dy) / np.where(ll > 0, ll, 1.0), 0.0)
        u = np.clip(u, 0.0, 1.0)
        return np.hypot(px - (sx0 + u * dx), py - (sy0 + u * dy))

    d = np.minimum(np.minimum(point_seg(ax0, ay0, bx0, by0, bx1, by1), point_seg(ax1, ay1, bx0, by0, bx1, by1)),
                   np.minimum(point_seg(bx0, by0, ax0, ay0, ax1, ay1), point_seg(bx1, by1, ax0, ay0, ax1, ay1)))

    def orient(px, py, qx, qy, rx, ry):
        return (qx - px) * (ry - py) - (qy - py) * (rx - px)

    o1 = orient(ax0, ay0, ax1, ay1, bx0, by0)
    o2 = orient(ax0, ay0, ax1, ay1, bx1, by1)
    o3 = orient(bx0, by0, bx1, by1, ax0, ay0)
    o4 = orient(bx0, by0, bx1, by1, ax1, ay1)
    crossing = (o1 * o2 < 0) & (o3 * o4 < 0)
    return np.where(crossing, 0.0, d)


def _min_quartic(c0, c1, k) -> tuple[float, float]:
    """Minimum over s in [0, 1] of |c0 + c1 s + k s^2|^2 (2D vectors), and
    where: the endpoints and the real critical points (roots of the cubic
    derivative)."""
    a3 = 2.0 * (k[0] * k[0] + k[1] * k[1])
    a2 = 3.0 * (c1[0] * k[0] + c1[1] * k[1])
    a1 = 2.0 * (c0[0] * k[0] + c0[1] * k[1]) + c1[0] * c1[0] + c1[1] * c1[1]
    a0 = c0[0] * c1[0] + c0[1] * c1[1]
    cands = [0.0, 1.0]
    coeffs = [a3, a2, a1, a0]
    if any(coeffs[:3]):
        for r in np.roots(coeffs):
            x = float(np.real(r))
            if 0.0 < x < 1.0:
                cands.append(x)
    best = (math.inf, 0.0)
    for sv in cands:
        rx = c0[0] + c1[0] * sv + k[0] * sv * sv
        ry = c0[1] + c1[1] * sv + k[1] * sv * sv
        f = rx * rx + ry * ry
        if f < best[0]:
            best = (f, sv)
    return math.sqrt(best[0]), best[1]


def _min_quadratic(c0, c1, k) -> tuple[float, float]:
    """Minimum over s in [0, 1] of c0 + c1 s + k s^2, and where."""
    cands = [0.0, 1.0]
    if k != 0.0:
        v = -c1 / (2.0 * k)
        if 0.0 < v < 1.0:
            cands.append(v)
    return min((c0 + c1 * sv + k * sv * sv, sv) for sv in cands)


def _exact(A: Track, ka: int, B: Track, kb: int, ts: float, te: float, gantry: int | None):
    """Closest approach of heads A (piece ka) and B (piece kb) over [ts, te]:
    (distance, or the gap along axis ``gantry``, time, A's XY, B's XY). Exact: each phase pair is a
    quadratic in time per axis."""
    cuts = {ts, te}
    for tr, k in ((A, ka), (B, kb)):
        for c in tr.phase_times(k):
            if ts < c < te:
                cuts.add(c)
    cuts = sorted(cuts)
    best = (math.inf, ts, None, None)
    for t0, t1 in zip(cuts[:-1], cuts[1:]):
        T = t1 - t0
        if T <= 0:
            continue
        tm = 0.5 * (t0 + t1)
        xa, ya, vxa, vya, axa, aya = A.state(ka, t0, tm)
        xb, yb, vxb, vyb, axb, ayb = B.state(kb, t0, tm)
        # relative position r(s) = c0 + c1 s + k s^2 with s = (t - t0) / T in [0, 1]
        c0 = (xb - xa, yb - ya)
        c1 = ((vxb - vxa) * T, (vyb - vya) * T)
        k = (0.5 * (axb - axa) * T * T, 0.5 * (ayb - aya) * T * T)
        if gantry is not None:
            d, sv = _min_quadratic(c0[gantry], c1[gantry], k[gantry])
        else:
            d, sv = _min_quartic(c0, c1, k)
        if d < best[0]:
            tt = t0 + sv * T
            pa = A.state(ka, tt, tm)[:2]
            pb = B.state(kb, tt, tm)[:2]
            best = (d, tt, pa, pb)
    return best


def moving_systems(mm: MultiReplay) -> list[int]:
    return [s for s, st in enumerate(mm.streams) if any(e[0] == "m" for e in st.events)]


def check_settings(mm: MultiReplay) -> None:
    """RepRapFirmware 3.5 keeps M204 per motion system, and axis limits per axis:
    a system that moves without its own M204, or whose axis letters no M201, M203
    or M566 names (when the file sets them at all), runs at the firmware's
    defaults, not at what the file assumes."""
    check = mm.checks["settings"]
    moving = moving_systems(mm)
    details = {"M204": sorted(mm.per_system_set), "axis_settings": sorted(mm.axis_settings_used)}
    check.details.update(details)
    if not moving:
        check.skip("no motion system moves")
        return
    any_m204 = any("M204" in v for v in mm.per_system_set.values())
    for s in moving:
        if any_m204 and "M204" not in mm.per_system_set.get(s, set()):
            check.fail(None, f"motion system {s} moves without an M204 of its own: it runs at the firmware's "
                             "default accelerations (M204 is per motion system)")
        for cmd in REQUIRED_AXIS_SETTINGS:
            if cmd not in mm.axis_settings_used:
                continue
            for role in "XY":
                letter = mm.systems[s].axes.get(role, role)
                if (cmd, letter) not in mm.axis_settings.get(s, set()):
                    check.fail(None, f"no {cmd} names axis {letter} (motion system {s}'s {role}): it runs at "
                                     "the firmware's default")


def check_end(mm: MultiReplay) -> None:
    """Every heater the job heated is off when it ends."""
    check = mm.checks["end"]
    on = {str(k): h.target for k, h in mm.heaters.items() if h.target > 0.0}
    check.details["heaters_on"] = dict(sorted(on.items()))
    for k, t in sorted(on.items()):
        what = "the bed" if k == gr.BED else f"heater {k}"
        check.fail(None, f"{what} is left at {t:g} degC at the end of the job")


def check_waits(mm: MultiReplay, tl: dict) -> None:
    """A system that waits at an M598 with its nozzle loaded (hot, filament not
    pulled back) oozes onto the part for as long as it waits. Which system waits
    depends on the machine's pace: replay with ``--perturb`` to see a file's
    barriers hold when one system runs slower than the file assumes."""
    check = mm.checks["waits"]
    loaded = sum(len(v) for v in mm.loaded_at.values())
    waited = [p["loaded_wait_s"] for p in tl["streams"]]
    check.details.update({"loaded_barriers": loaded, "loaded_wait_s": waited,
                          "loaded_waits": sum(len(p["loaded_waits"]) for p in tl["streams"])})
    for s, p in enumerate(tl["streams"]):
        for w, line in p["loaded_waits"]:
            check.fail(line, f"motion system {s} waits {w:.3f} s here with its nozzle loaded (filament not "
                             "pulled back)")


def check_collisions(mm: MultiReplay, tl: dict) -> dict:
    """Every pair of heads over the whole build: envelopes (discs) must not
    overlap, or with a shared gantry the higher-numbered head must stay at
    least the radii's sum to the right (+X) of the lower-numbered one."""
    # The axis along which gantry-borne heads keep their order (0: X on one shared
    # gantry, 1: Y on two gantries), or None for discs.
    gantry = 0 if mm.shared_gantry else 1 if mm.dual_gantry else None
    out = {"mode": {0: "shared-gantry", 1: "dual-gantry"}.get(gantry, "discs"), "count": 0, "pairs": [], "examples": [],
           "unchecked_s": 0.0, "closest_mm": None, "closest_at_s": None, "intervals": 0, "solved_exactly": 0}
    check = mm.checks["collisions"]
    systems = mm.systems
    missing = [s.number for s in systems if s.radius is None]
    active = [s for s, st in enumerate(mm.streams) if any(e[0] in ("m", "d") for e in st.events)]
    if len(active) < 2:
        check.skip("fewer than two motion systems move")
        return out
    if missing:
        check.skip("no envelope radius for motion system(s) " + ", ".join(map(str, missing))
                   + " (--head-radius, --envelope or the file's '; motion system <n>: ... envelope <r> mm')")
        return out
    T = tl["build_s"]
    tracks = tl["tracks"]
    closest = (math.inf, None)
    for i in range(len(systems)):
        for j in range(i + 1, len(systems)):
            A, B = tracks[i], tracks[j]
            need = systems[i].radius + systems[j].radius
            starts = np.union1d(A.t0, B.t0)
            starts = starts[starts < T]
            if len(starts) == 0 or starts[0] > 0:
                starts = np.concatenate([[0.0], starts])
            ends = np.append(starts[1:], T)
            keep = ends - starts > 1e-12
            starts, ends = starts[keep], ends[keep]
            ia = np.clip(np.searchsorted(A.t0, starts, side="right") - 1, 0, A.n - 1)
            ib = np.clip(np.searchsorted(B.t0, starts, side="right") - 1, 0, B.n - 1)
            ax0, ay0 = A.xy(ia, starts)
            ax1, ay1 = A.xy(ia, ends)
            bx0, by0 = B.xy(ib, starts)
            bx1, by1 = B.xy(ib, ends)
            unknown = np.isnan(ax0) | np.isnan(bx0)
            # Within an interval each head moves monotonically along a straight
            # line: it stays on the segment between its positions at the ends.
            # The segments' distance (or X gap) is a lower bound of the heads'.
            if gantry == 0:
                lower = np.minimum(bx0, bx1) - np.maximum(ax0, ax1)
            elif gantry == 1:
                lower = np.minimum(by0, by1) - np.maximum(ay0, ay1)
            else:
                lower = _segment_distance(ax0, ay0, ax1, ay1, bx0, by0, bx1, by1)
            lower = np.where(unknown, np.inf, lower)
            unchecked = float((ends - starts)[unknown].sum())
            out["unchecked_s"] += unchecked
            cand = np.flatnonzero(lower < need - OVERLAP_TOL)
            out["intervals"] += int(len(starts))
            out["solved_exactly"] += int(len(cand))
            # closest approach: exact where solved, the lower bound elsewhere
            rest = lower.copy()
            rest[cand] = np.inf
            pair_closest = (float(rest.min()), float(starts[int(np.argmin(rest))])) if len(rest) else (math.inf, None)
            episodes = 0
            prev_k = None
            cur = None
            for k in cand.tolist():
                d, tt, pa, pb = _exact(A, int(ia[k]), B, int(ib[k]), float(starts[k]), float(ends[k]), gantry)
                if d < pair_closest[0]:
                    pair_closest = (d, tt)
                if d >= need - OVERLAP_TOL:
                    prev_k = None
                    continue
                if prev_k is not None and prev_k == k - 1 and cur is not None:
                    if d < cur["distance_mm"]:
                        cur.update({"time_s": tt, "distance_mm": d, "positions": {str(i): list(pa), str(j): list(pb)},
                                    "lines": {str(i): int(A.line[ia[k]]), str(j): int(B.line[ib[k]])}})
                    cur["end_s"] = float(ends[k])
                else:
                    episodes += 1
                    cur = {"systems": [i, j], "start_s": float(starts[k]), "end_s": float(ends[k]), "time_s": tt,
                           "distance_mm": d, "required_mm": need,
                           "positions": {str(i): list(pa), str(j): list(pb)},
                           "lines": {str(i): int(A.line[ia[k]]), str(j): int(B.line[ib[k]])}}
                    if len(out["examples"]) < MAX_COLLISIONS:
                        out["examples"].append(cur)
                    what = {0: "X gap", 1: "Y gap"}.get(gantry, "distance")
                    check.fail(max(int(A.line[ia[k]]), int(B.line[ib[k]])),
                               f"heads {i} and {j} at t = {tt:.3f} s: {what} {d:.3f} mm < {need:g} mm "
                               f"(head {i} at ({pa[0]:.3f}, {pa[1]:.3f}), line {int(A.line[ia[k]])}; head {j} at "
                               f"({pb[0]:.3f}, {pb[1]:.3f}), line {int(B.line[ib[k]])})")
                prev_k = k
            out["count"] += episodes
            out["pairs"].append({"systems": [i, j], "required_mm": need, "collisions": episodes,
                                 "closest_mm": None if not math.isfinite(pair_closest[0]) else pair_closest[0],
                                 "closest_at_s": pair_closest[1], "unchecked_s": unchecked})
            if pair_closest[0] < closest[0]:
                closest = pair_closest
    if math.isfinite(closest[0]):
        out["closest_mm"], out["closest_at_s"] = closest
    if out["unchecked_s"] > 0:
        mm.warnings.append(f"collisions: a head's position is unknown for {out['unchecked_s']:.3f} s of the build "
                           "(before its first absolute move or after homing; give 'home X <x> Y <y>'): not checked then")
    return out


# ---------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------

def analyse_multi(text: str, opts: gr.Options, name: str = "<string>") -> dict:
    """Replays a job with several motion systems and returns the report."""
    mm = MultiReplay(opts, text)
    mm.run(text)
    return build_report_multi(mm, opts, name)


def _tool_key(k: int) -> str:
    return f"T{k}" if k >= 0 else "none"


def build_report_multi(mm: MultiReplay, o: gr.Options, name: str) -> dict:
    checks = mm.checks
    streams = mm.streams
    unknown: dict[str, int] = {}
    for st in streams:
        for k, v in st.unknown.items():
            unknown[k] = unknown.get(k, 0) + v
    checks["parse"].details["unknown_commands"] = dict(sorted(unknown.items()))
    if not mm.forked:
        mm.warnings.append("no M606 S1: the job is not forked")

    # Layers per stream: Z never decreases; heights. Merged by number for coverage.
    merged: dict[int, gr.Layer] = {}
    order: list[int] = []
    for s, st in enumerate(streams):
        mm.ctx.stream = s
        prev_z = None
        for lay in st.layers:
            if lay.z is not None:
                if prev_z is not None and lay.z < prev_z - gr.LAYER_Z_TOL:
                    checks["layers"].fail(lay.line, f"layer {lay.number} at Z {lay.z:.4f} is below the previous "
                                                    f"layer's Z {prev_z:.4f}")
                lay.height = lay.z - prev_z if prev_z is not None else lay.z
                prev_z = lay.z
            m = merged.get(lay.number)
            if m is None:
                m = merged[lay.number] = gr.Layer(ordinal=len(order), number=lay.number, line=lay.line,
                                                  z=lay.z, height=lay.height, sampled=lay.sampled)
                order.append(lay.number)
            elif m.z is None:
                m.z, m.height = lay.z, lay.height
            elif lay.z is not None and abs(lay.z - m.z) > gr.LAYER_Z_TOL:
                mm.warnings.append(f"layer {lay.number}: printed at Z {m.z:.4f} and at Z {lay.z:.4f} (system {s}); "
                                   "coverage uses the first")
            m.line = min(m.line, lay.line)
            m.sampled = m.sampled or lay.sampled
            m.segs.extend((a, b, c, d, e, s * 1_000_000_000 + run) for a, b, c, d, e, run in lay.segs)
            m.part_volume += lay.part_volume
    mm.ctx.stream = None
    if not any(st.layers for st in streams):
        checks["layers"].skip("no ;LAYER: markers")
    merged_layers = [merged[n] for n in order]

    volume_by_type: dict[str, float] = {}
    for st in streams:
        for k, v in st.volume_by_type.items():
            volume_by_type[k] = volume_by_type.get(k, 0.0) + v
    if not any(v > 0 for v in volume_by_type.values()):
        checks["features"].skip("no extrusion")
    if o.bed_rect is None and o.bed_circle is None:
        checks["bed"].skip("no --bed or --bed-circle given")
    mix_commands = sum(st.mix_commands for st in streams)
    if mix_commands == 0:
        checks["mixes"].skip("no mix commands")
    if not mm.separation:
        checks["separation"].skip("no M597 in the file")

    area = streams[0].area
    volumetric = any(st.volumetric for st in streams)
    part_volume = volume_by_type.get("PART", 0.0)
    volume = {"filament_diameter_mm": o.filament, "filament_area_mm2": area,
              "by_type_mm3": {k: round(v, 6) for k, v in sorted(volume_by_type.items())},
              "part_mm3": part_volume, "mesh_mm3": None, "ratio": None, "tolerance": o.volume_tol}
    mesh_data = None
    if o.mesh is not None:
        vtx, fcs = gr.load_mesh(o.mesh)
        mvol = abs(gr.mesh_volume(vtx, fcs))
        volume["mesh_mm3"] = mvol
        ratio = part_volume / mvol if mvol > 0 else None
        volume["ratio"] = ratio
        if ratio is None or abs(ratio - 1.0) > o.volume_tol:
            checks["volume"].fail(None, f"PART volume {part_volume:.3f} mm^3 is "
                                        f"{ratio if ratio is not None else float('nan'):.4f} x the mesh volume "
                                        f"{mvol:.3f} mm^3 (tolerance {o.volume_tol:g})")
        mesh_data = (vtx, fcs)
    else:
        checks["volume"].skip("no --mesh given")
    checks["volume"].details.update({"part_mm3": part_volume, "mesh_mm3": volume["mesh_mm3"], "ratio": volume["ratio"]})
    coverage = {"every": o.coverage_every, "bead_ends": o.bead_ends, "layers": [], "worst_coverage": None,
                "worst_overlap": None, "min": o.coverage_min, "overlap_max": o.overlap_max, "placement": None,
                "sampled_by": "layer number"}
    if mesh_data is not None:
        gr.coverage_check(SimpleNamespace(layers=merged_layers, checks=checks, area=area, volumetric=volumetric),
                          o, mesh_data, coverage)
    else:
        checks["coverage"].skip("no --mesh given")

    # Time
    tl = build_timeline(mm)
    build = tl["build_s"]
    tol = gr.time_tolerance(o, multi=True)
    est = mm.estimated
    time = {"replayed_s": build, "estimated_s": est[0] if est else None, "estimate_line": est[1] if est else None,
            "rel_error": None, "tolerance": tol,
            "sequential_s": mm.sequential[0] if mm.sequential else None,
            "sequential_line": mm.sequential[1] if mm.sequential else None,
            "ratio_to_sequential": None,
            "streams_sum_s": sum(p["busy_s"] for p in tl["streams"]),
            "layers_busiest_s": tl["layers_busiest_s"],
            "layers_busiest_print_s": tl["layers_busiest_print_s"],
            # Tool changes are dwells of their stream, heating waits waits of their stream.
            "heating_wait_s": tl["heating_wait_s"],
            "tool_change_s": sum(st.tool_change_s for st in streams),
            "heating_waits": tl["heating_waits"][:gr.MAX_EXAMPLES],
            "heating_model": gr.heating_model(streams[0]) if streams else None,
            "barriers": len(mm.barriers),
            "barrier_kinds": {},
            "junction": [("jerk" if st.jerk is not None else f"junction deviation {st.jd:g} mm") for st in streams]}
    for b in mm.barriers:
        time["barrier_kinds"][b["kind"]] = time["barrier_kinds"].get(b["kind"], 0) + 1
    if mm.sequential and mm.sequential[0] > 0:
        time["ratio_to_sequential"] = build / mm.sequential[0]
    if mm.o.perturb:
        checks["time"].skip("--perturb times a machine slower than the file's estimate assumes")
    elif est is None:
        checks["time"].skip("no '; estimated printing time: <seconds> s' line")
    else:
        rel = (est[0] - build) / build if build > 0 else (0.0 if est[0] == 0 else math.inf)
        time["rel_error"] = rel
        if abs(rel) > tol:
            checks["time"].fail(est[1], f"file estimates {est[0]:.1f} s, replay gives {build:.1f} s ({rel * 100:+.1f} %)")
    checks["time"].details.update({"replayed_s": build, "estimated_s": time["estimated_s"], "rel_error": time["rel_error"],
                                   "ratio_to_sequential": time["ratio_to_sequential"]})

    # Extrusion per tool and stream
    by_stream = {}
    fil_tool: dict[int, float] = {}
    part_tool: dict[int, float] = {}
    for s, st in enumerate(streams):
        by_stream[str(s)] = {
            "filament_mm": {_tool_key(k): v for k, v in sorted(st.filament_by_tool.items())},
            "volume_mm3": {_tool_key(k): v * area for k, v in sorted(st.filament_by_tool.items())},
            "part_mm3": {_tool_key(k): v for k, v in sorted(st.part_by_tool.items())},
        }
        for k, v in st.filament_by_tool.items():
            fil_tool[k] = fil_tool.get(k, 0.0) + v
        for k, v in st.part_by_tool.items():
            part_tool[k] = part_tool.get(k, 0.0) + v
    extrusion = {"tolerance": o.extrusion_tol, "by_stream": by_stream,
                 "filament_mm": {_tool_key(k): v for k, v in sorted(fil_tool.items())},
                 "volume_mm3": {_tool_key(k): v * area for k, v in sorted(fil_tool.items())},
                 "part_mm3": {_tool_key(k): v for k, v in sorted(part_tool.items())},
                 "planned_mm3": {f"T{k}": v for k, (v, _l) in sorted(mm.planned.items())},
                 "rel_error": {}}
    if not mm.planned:
        checks["extrusion"].skip("no '; planned extrusion T<n>: <mm3> mm3' lines")
    else:
        for k, (plan, line) in sorted(mm.planned.items()):
            got = part_tool.get(k, 0.0)
            rel = (got - plan) / plan if plan > 0 else (0.0 if got == 0 else math.inf)
            extrusion["rel_error"][f"T{k}"] = rel
            if abs(rel) > o.extrusion_tol:
                checks["extrusion"].fail(line, f"T{k} deposits {got:.3f} mm^3 of PART, planned {plan:.3f} mm^3 "
                                               f"({rel * 100:+.2f} %, tolerance {o.extrusion_tol * 100:g} %)")
        for k, got in sorted(part_tool.items()):
            if k not in mm.planned and got > 0:
                checks["extrusion"].fail(None, f"{_tool_key(k)} deposits {got:.3f} mm^3 of PART with no planned line")
    checks["extrusion"].details.update({"part_mm3": extrusion["part_mm3"], "planned_mm3": extrusion["planned_mm3"],
                                        "rel_error": extrusion["rel_error"]})

    mm.ctx.stream = None
    check_settings(mm)
    check_end(mm)
    check_waits(mm, tl)

    collisions = check_collisions(mm, tl)
    checks["collisions"].details.update({"count": collisions["count"], "mode": collisions["mode"],
                                         "closest_mm": collisions["closest_mm"],
                                         "unchecked_s": collisions["unchecked_s"]})
    checks["streams"].details.update({"forked": mm.forked, "barriers": len(mm.barriers)})

    stream_rows = []
    for s, st in enumerate(streams):
        p = tl["streams"][s]
        zs = [lay.z for lay in st.layers if lay.z is not None]
        stream_rows.append({
            "system": s,
            "commands": st.commands,
            "moves": len(st.moves),
            "busy_s": p["busy_s"],
            "wait_s": p["wait_s"],
            "paused_share": p["wait_s"] / build if build > 0 else 0.0,
            "end_s": p["end_s"],
            "dwell_s": p["dwell_s"],
            "heating_wait_s": p["heating_wait_s"],
            "by_kind_s": p["by_kind_s"],
            "longest_wait_s": max(p["waits"], default=0.0),
            "loaded_wait_s": p["loaded_wait_s"],
            "tools": sorted(_tool_key(k) for k in st.filament_by_tool),
            "tool_selections": len(st.tool_selects),
            "filament_mm": by_stream[str(s)]["filament_mm"],
            "volume_mm3": by_stream[str(s)]["volume_mm3"],
            "part_mm3": by_stream[str(s)]["part_mm3"],
            "layers": {"count": len(st.layers), "with_extrusion": len(zs),
                       "z_first": zs[0] if zs else None, "z_last": zs[-1] if zs else None},
            "extents": _bbox(st.extents["moves"]),
        })

    def union(key):
        e = [math.inf, math.inf, -math.inf, -math.inf]
        for st in streams:
            x = st.extents[key]
            e = [min(e[0], x[0]), min(e[1], x[1]), max(e[2], x[2]), max(e[3], x[3])]
        return _bbox(e)

    warnings = list(mm.warnings)
    for s, st in enumerate(streams):
        warnings.extend(f"system {s}: {w}" for w in st.warnings)
    zs_all = [lay.z for lay in merged_layers if lay.z is not None]
    report = {
        "file": name,
        "mode": "multi-motion",
        "ok": all(c.status != "fail" for c in checks.values()),
        "flavor": "rrf",
        "flavor_from": mm.flavor_from,
        "mixing": mm.mixing,
        "lines": mm.line,
        "checks": {k: c.to_json() for k, c in checks.items()},
        "motion_systems": {"systems": [s.to_json() for s in mm.systems], "shared_gantry": mm.shared_gantry, "dual_gantry": mm.dual_gantry,
                           "shared_gantry_from": mm.shared_gantry_from, "forked": mm.forked,
                           "shared_axes": sorted(mm.shared_letters),
                           "separation_rules": mm.separation},
        "streams": stream_rows,
        "layers": {"count": len(merged_layers), "with_extrusion": len(zs_all),
                   "z_first": zs_all[0] if zs_all else None, "z_last": zs_all[-1] if zs_all else None},
        "volume": volume,
        "coverage": coverage,
        "time": time,
        "extrusion": extrusion,
        "collisions": collisions,
        "tools": {
            "changes": sum(st.tool_changes for st in streams),
            "selections": sum(len(st.tool_selects) for st in streams),
            "filament_mm": extrusion["filament_mm"],
            "volume_mm3": extrusion["volume_mm3"],
        },
        "mix": {"commands": mix_commands, "changes": sum(st.mix_changes for st in streams),
                "channels": max(st.mix_channels for st in streams)},
        "extents": {"moves": union("moves"), "extrusion": union("extrusion")},
        "unknown_commands": dict(sorted(unknown.items())),
        "warnings": warnings[:gr.MAX_EXAMPLES],
        "options": {
            **gr.options_report(o, tol),
            "head_radius": o.head_radius, "envelopes": {str(k): v for k, v in o.envelopes.items()},
            "axis_maps": {str(k): v for k, v in o.axis_maps.items()},
            "homes": {str(k): list(v) for k, v in o.homes.items()},
            "shared_gantry": o.shared_gantry, "dual_gantry": o.dual_gantry, "extrusion_tol": o.extrusion_tol,
            "perturb": {str(k): list(v) for k, v in o.perturb.items()},
        },
    }
    return report


def _bbox(e):
    return None if not math.isfinite(e[0]) else {"x_min": e[0], "y_min": e[1], "x_max": e[2], "y_max": e[3],
                                                   "width": e[2] - e[0], "depth": e[3] - e[1]}


def summary_multi(rep: dict) -> str:
    out = []
    ms = rep["motion_systems"]
    out.append(f"{rep['file']}: {rep['lines']} lines, RepRapFirmware, {len(ms['systems'])} motion systems"
               + ("" if ms["forked"] else " (NOT forked: no M606 S1)")
               + (", mixing" if rep["mixing"] else ""))
    for s in ms["systems"]:
        axes = ", ".join(f"{r}={L}" for r, L in s["axes"].items())
        env = f"{s['envelope_mm']:g} mm" if s["envelope_mm"] is not None else "none"
        out.append(f"  system {s['system']}: axes {axes}; envelope {env}")
    t = rep["time"]
    est = f"{t['estimated_s']:.1f} s" if t["estimated_s"] is not None else "none"
    line = f"build time: replayed {t['replayed_s']:.1f} s over {t['barriers']} barriers, file estimate {est}"
    if t["sequential_s"] is not None:
        line += f"; sequential {t['sequential_s']:.1f} s, ratio {t['ratio_to_sequential']:.3f}"
    out.append(line)
    if t["heating_model"] is not None or t["tool_change_s"]:
        out.append(f"  heating waits {t['heating_wait_s']:.1f} s (summed over the streams"
                   + ("" if t["heating_model"] else "; not modelled: no --heating-rate")
                   + f"), tool changes {t['tool_change_s']:.1f} s")
    out.append(f"  per layer, the busiest stream's moves add up to {t['layers_busiest_s']:.1f} s "
               f"(these moves side by side, never waiting; all streams' moves {t['streams_sum_s']:.1f} s); "
               f"its printing moves alone {t['layers_busiest_print_s']:.1f} s")
    for row in rep["streams"]:
        fil = ", ".join(f"{k} {v:.1f} mm" for k, v in row["filament_mm"].items()) or "no extrusion"
        out.append(f"  stream {row['system']}: busy {row['busy_s']:.1f} s, waits {row['wait_s']:.1f} s "
                   f"({row['paused_share'] * 100:.1f} % paused), {row['moves']} moves; {fil}")
    ex = rep["extrusion"]
    if ex["part_mm3"] or ex["planned_mm3"]:
        parts = []
        for k in sorted(set(ex["part_mm3"]) | set(ex["planned_mm3"])):
            got = ex["part_mm3"].get(k, 0.0)
            plan = ex["planned_mm3"].get(k)
            parts.append(f"{k} {got:.1f}" + (f" (planned {plan:.1f})" if plan is not None else ""))
        out.append("PART mm^3 per tool: " + ", ".join(parts))
    c = rep["collisions"]
    closest = f"{c['closest_mm']:.3f} mm" if c["closest_mm"] is not None else "n/a"
    out.append(f"collisions ({c['mode']}): {c['count']}; closest approach {closest}"
               + (f"; {c['unchecked_s']:.1f} s unchecked" if c["unchecked_s"] else ""))
    vol = rep["volume"]
    if vol["mesh_mm3"] is not None:
        out.append(f"PART {vol['part_mm3']:.1f} mm^3 vs mesh {vol['mesh_mm3']:.1f} mm^3: ratio {vol['ratio']:.4f}")
    if rep["unknown_commands"]:
        out.append("unknown commands: " + ", ".join(f"{k} x{v}" for k, v in rep["unknown_commands"].items()))
    out.extend(gr.checks_summary(rep, 10))
    return "\n".join(out)
