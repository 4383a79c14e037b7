"""Quality figures of a bake, frame by frame: what a render would show wrong, in numbers.

The driver hands each written frame's world to :class:`QualityRecorder`, which asks the core
for the figures (a ``QualityMeter``: ``World.quality()`` measured again only where something
can have changed; measured apart from the solver: core/world/quality.h)
and keeps them with the frame's substeps, wall time and kinetic energy. At the end they go
into a sidecar ``CACHE.qa.json`` (written whole or not at all), a summary into the cache's
``customLayerData["simbake"]["qa"]``, and one warning line per figure that crossed its
threshold.

Thresholds (``THRESHOLDS``; a figure *above* its threshold is a warning):

* ``body_penetration``: 5 mm. A dynamic body's surface sample inside another body or the
  ground. The contact solver keeps resting contacts within 0.2 mm; 5 mm is ~5 pixels of a
  2 m wide shot at 1080p, where a render starts to show it.
* ``cloth_penetration``: 1 mm past a body's or the ground's surface, at a cloth vertex or
  an edge's eighths (the cloth's thickness not counted): the cloth keeps its
  thickness (5 mm by default) away from surfaces, so anything past the surface is a miss.
* ``cloth_strain``: the cloth's ``strain_limit`` plus 1% of it (no threshold when 0).
* ``cloth_self_intersections``: 0 crossing pairs of triangles (a layer through another); a
  cloth's count is -1 at a frame where it was too crumpled to count within the work budget
  (warned).
* ``substeps``: a frame whose automatic substeps reached the solver's cap (``max_substeps``,
  4096); none when the scene fixes its substeps (its own choice, up to that cap).
* ``energy_gain``, ``unexplained_stop``, ``imparted_speed``: energy made up by the solver, a
  body stopping in mid-air, a body launched faster than anything but a keyed body could make
  it (simbake.qa_motion, where each is defined with its threshold).
* ``joint_error``: 1 mm (scenes with joints). The largest gap between a joint's two frames
  along what the joint holds (its origins for a ball, hinge or fixed joint; off the axis for a
  slider; past the range for a distance joint), over the joints not broken. The solver closes
  joints to well under a micrometre; a millimetre at a chain link or a hinge shows in a
  close-up.
* ``attachment_drift``: 1 mm (scenes with cloth attachments). The largest distance of an
  attached cloth point from where its body carries it (its bound surface point and offset, at
  the body's pose or the deforming collider's own mesh at that frame: simbake.qa_attachments,
  measured apart from the solver). The solver puts them there exactly; a millimetre is a seam
  that visibly opens.
* ``cloth_fallbacks``: 0. The cloth steps' fallbacks in the frame (README, "Bounded work"):
  steps a cloth held still (its impact zones did not settle, or its self-collision ran out
  of its work budget), impact zones a keyed body would have pressed into the ground, steps
  in which a cloth let a keyed body through it, and steps in which a cloth was stretched
  past three times its strain limit. Each is a place the cloth could not do what it was
  asked to.

The JSON layout (version 1)::

    {"simbake_qa": 2, "cache": ..., "cache_sha256": ..., "scene": {...}, "thresholds": {...},
     "frames": [...], "time": [...],            # frame numbers, seconds from the start
     "figures": {"substeps": [...], "wall_seconds": [...], "kinetic_energy": [...],
                 "body_penetration": [...], "body_penetration_between": [[a, b] | null],
                 "cloth_penetration": [...], "cloth_strain": [...],
                 "cloth_self_intersections": [...], "cloth_fallbacks": [...],
                 "energy_gain": [...],
                 "unexplained_stop": [...], "unexplained_stop_body": [name | null],
                 "imparted_speed": [...], "imparted_speed_body": [name | null],
                 "joint_error": [...], "joint_error_joint": [name | null],    # (with joints)
                 "attachment_drift": [...]},                                   # (with attachments)
     "cloths": {name: {"strain": [...], "self_intersections": [...],
                       "vertex_penetration": [...], "edge_penetration": [...],
                       "attachment_drift": [...]}},                            # (attached cloths)
     "summary": {figure: {"worst": v, "frame": f, "threshold": t, "first_over": f | null}},
     "warnings": [...], "profile": {stage: seconds}}

Lengths are metres, energies joules, speeds metres per second, times seconds.
``cache_sha256`` is the SHA-256 of the cache file the sidecar was written with: ``simbake
report`` uses a sidecar only beside that very file.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path
from typing import Any

from .files import sha256_of, write_atomically
from .qa_attachments import AttachmentDrift, has_attachments
from .qa_deforming import DeformingPenetration, has_deforming
from .qa_motion import MotionFigures
from .scene import Scene

QA_VERSION = 2
BODY_PENETRATION = 5e-3       # (m)
CLOTH_PENETRATION = 1e-3      # (m)
JOINT_ERROR = 1e-3            # (m)
ATTACHMENT_DRIFT = 1e-3       # (m)
STRAIN_MARGIN = 0.01          # of the strain limit
MAX_SUBSTEPS = 4096           # the core's WorldSettings.max_substeps
# World.statistics() counters of the cloth step's fallbacks (README "Bounded work"), summed
FALLBACKS = ("cloth_held_still", "self_collision_over_budget", "impact_zone_yields", "cloth_let_in", "cloth_gave")


_SCALARS = (int, bool, str)    # (_plain's values as they are)
_SETTINGS = "simbake:settings"  # where the scene's settings go into the sidecar's text
_MOTION = ("energy_gain", "unexplained_stop", "unexplained_stop_body", "imparted_speed", "imparted_speed_body")


def qa_path(cache: str | Path) -> Path:
    """The sidecar of a cache: out.usdc -> out.qa.json."""
    cache = Path(cache)
    return cache.with_name(cache.stem + ".qa.json")


def thresholds(scene: Scene) -> dict[str, float | None]:
    """Each figure's threshold for this scene (None: never a warning)."""
    limits = [c.strain_limit for c in scene.cloths if c.strain_limit > 0]
    return {
        "body_penetration": BODY_PENETRATION,
        "cloth_penetration": CLOTH_PENETRATION if scene.cloths else None,
        # per cloth (its own limit); this is the largest, for the summary
        "cloth_strain": max(limits) * (1 + STRAIN_MARGIN) if limits else None,
        "cloth_self_intersections": 0 if scene.cloths else None,
        "substeps": MAX_SUBSTEPS - 1 if scene.substeps == 0 else None,  # a fixed count is the scene's
        "cloth_fallbacks": 0 if scene.cloths else None,
        **({"joint_error": JOINT_ERROR} if scene.joints else {}),
        **({"attachment_drift": ATTACHMENT_DRIFT} if has_attachments(scene) else {}),
        "kinetic_energy": None,
        "wall_seconds": None,
    }


class QualityRecorder:
    """Collects the quality figures of every written frame of one bake."""

    def __init__(self, scene: Scene, motion: MotionFigures | None = None):
        self.scene = scene
        self.motion = motion
        self.body_names = [b.name for b in scene.bodies]
        self.cloth_names = [c.name for c in scene.cloths]
        self.limits = {c.name: (c.strain_limit * (1 + STRAIN_MARGIN) if c.strain_limit > 0 else None)
                       for c in scene.cloths}
        self.frames: list[int] = []
        self.figures: dict[str, list] = {k: [] for k in (
            "substeps", "wall_seconds", "kinetic_energy", "body_penetration",
            "body_penetration_between", "cloth_penetration", "cloth_strain",
            "cloth_self_intersections", "cloth_fallbacks") + (_MOTION if motion is not None else ())
            + (("joint_error", "joint_error_joint") if scene.joints else ())
            + (("attachment_drift",) if has_attachments(scene) else ())}
        self.joint_names = [j.name for j in scene.joints]
        self._fallbacks = 0  # the fallbacks counted up to the last recorded frame
        self._meter = None   # the core's QualityMeter, made at the first frame
        self.cloths: dict[str, dict[str, list]] = {
            name: {"strain": [], "self_intersections": [], "vertex_penetration": [],
                   "edge_penetration": []} for name in self.cloth_names}
        # cloth inside a deforming collider at its own pose (simbake.qa_deforming)
        self.deforming = DeformingPenetration(scene) if has_deforming(scene) and scene.cloths else None
        # attached cloth points against where their body carries them (simbake.qa_attachments)
        self.attachments = AttachmentDrift(scene) if has_attachments(scene) else None
        for c in scene.cloths:
            if c.attached:
                self.cloths[c.name]["attachment_drift"] = []

    @property
    def thresholds(self) -> dict[str, float | None]:
        """Each figure's threshold (the energy's depends on the whole bake: known at the end)."""
        return {**thresholds(self.scene), **(self.motion.thresholds() if self.motion is not None else {})}

    def record(self, frame: int, world, substeps: int, wall_seconds: float, origins=None) -> None:
        """The figures of `world` as it is now, written as `frame`; `origins` (bodies, 3): the
        bodies' mesh origins (m), for the motion figures."""
        if self._meter is None:
            from . import _core  # (the compiled core loads with the world, not with this module)

            self._meter = _core.QualityMeter()
        quality = self._meter.measure(world)
        self.frames.append(frame)
        f = self.figures
        f["substeps"].append(int(substeps))
        f["wall_seconds"].append(float(wall_seconds))
        stats = world.statistics(penetrations=False)
        f["kinetic_energy"].append(float(stats["kinetic_energy"]))
        fallbacks = sum(int(stats.get(k, 0)) for k in FALLBACKS)
        f["cloth_fallbacks"].append(fallbacks - self._fallbacks)
        self._fallbacks = fallbacks
        if self.motion is not None:
            self._record_motion(frame, world, origins, quality["body_penetration"][0] > BODY_PENETRATION)
        depth, a, b = quality["body_penetration"]
        f["body_penetration"].append(float(depth))
        f["body_penetration_between"].append(
            [self.body_names[a], self.body_names[b] if b >= 0 else "ground"] if a >= 0 else None)
        deepest, strain, crossings = 0.0, 0.0, 0
        for name, q in zip(self.cloth_names, quality["cloths"]):
            c = self.cloths[name]
            c["strain"].append(float(q["max_strain"]))
            c["self_intersections"].append(int(q["self_intersections"]))
            c["vertex_penetration"].append(float(q["vertex_penetration"][0]))
            c["edge_penetration"].append(float(q["edge_penetration"][0]))
            deepest = max(deepest, c["vertex_penetration"][-1], c["edge_penetration"][-1])
            strain = max(strain, c["strain"][-1])
            crossings += max(c["self_intersections"][-1], 0)  # (-1: not counted, warned below)
        f["cloth_penetration"].append(deepest)
        if self.deforming is not None:
            self.deforming.fold_into(self.cloths, f, frame, world)
        f["cloth_strain"].append(strain)
        f["cloth_self_intersections"].append(crossings)
        if self.joint_names:
            self._record_joints(world)
        if self.attachments is not None:
            drift = self.attachments.measure(frame, world)
            for k, value in drift.items():
                self.cloths[self.cloth_names[k]]["attachment_drift"].append(value)
            f["attachment_drift"].append(max(drift.values()))

    def _record_joints(self, world) -> None:
        """The largest gap of any joint not broken, and which joint."""
        states = world.joint_states()
        gaps = [float(g) if e else 0.0 for g, e in zip(states["gap"], states["enabled"])]
        worst = max(range(len(gaps)), key=lambda k: (gaps[k], -k))
        self.figures["joint_error"].append(gaps[worst])
        self.figures["joint_error_joint"].append(self.joint_names[worst] if gaps[worst] > 0 else None)

    def _record_motion(self, frame: int, world, origins, overlapping: bool) -> None:
        time = (frame - self.scene.start_frame) / self.scene.fps
        m = self.motion.record(world, time, origins, overlapping)
        f = self.figures
        if len(self.frames) == 1:  # before any step the core has no statistics yet
            f["kinetic_energy"][-1] = self.motion.largest_kinetic
        for name, who in (("energy_gain", None), ("unexplained_stop", "stopped_body"),
                          ("imparted_speed", "fastest_body")):
            f[name].append(float(m[name]))
            if who is not None:
                f[f"{name}_body"].append(self.body_names[m[who]] if m[who] >= 0 and m[name] > 0 else None)

    # -- results -------------------------------------------------------------------------------

    def summary(self) -> dict[str, dict[str, Any]]:
        """Per figure: its worst value and frame, its threshold and the first frame over it."""
        out = {}
        for name, threshold in self.thresholds.items():
            values = self.figures[name]
            if not values or (name.startswith("cloth_") and not self.cloth_names):
                continue
            worst = max(range(len(values)), key=lambda k: (values[k], -k))
            first = None
            if name == "cloth_strain":
                first = self._first_strain_over()
            elif threshold is not None:
                first = next((self.frames[k] for k, v in enumerate(values) if v > threshold), None)
            out[name] = {"worst": values[worst], "frame": self.frames[worst],
                         "threshold": threshold, "first_over": first}
        return out

    def _first_strain_over(self) -> int | None:
        """The first frame at which some cloth's strain passed its own limit."""
        firsts = [next((self.frames[k] for k, v in enumerate(self.cloths[n]["strain"]) if v > limit), None)
                  for n, limit in self.limits.items() if limit is not None]
        firsts = [f for f in firsts if f is not None]
        return min(firsts) if firsts else None

    def warnings(self, sidecar: str | Path) -> list[str]:
        """One line per figure (per cloth for the cloth figures) over its threshold, naming
        the worst frame, the first frame over and the figure."""
        lines = []

        def over(label: str, values: list, threshold: float | None, unit: str, scale: float,
                 where=lambda k: "") -> None:
            if threshold is None:
                return
            first = next((k for k, v in enumerate(values) if v > threshold), None)
            if first is None:
                return
            worst = max(range(len(values)), key=lambda k: (values[k], -k))
            lines.append(f"QA: {label} {_show(values[worst], unit, scale)}{where(worst)} at frame "
                         f"{self.frames[worst]} (over {_show(threshold, unit, scale)} from frame "
                         f"{self.frames[first]}); see {sidecar}")

        between = self.figures["body_penetration_between"]
        over("deepest body penetration", self.figures["body_penetration"], self.thresholds["body_penetration"],
             "mm", 1e3, lambda k: f" ({between[k][0]} into {between[k][1]})" if between[k] else "")
        for name, c in self.cloths.items():
            depth = [max(v, e) for v, e in zip(c["vertex_penetration"], c["edge_penetration"])]
            over(f"cloth {name!r} penetration", depth, CLOTH_PENETRATION, "mm", 1e3)
            over(f"cloth {name!r} strain", c["strain"], self.limits[name], "%", 1e2)
            over(f"cloth {name!r} self-intersections", c["self_intersections"], 0, "pairs", 1)
            if "attachment_drift" in c:
                over(f"cloth {name!r} attached points off their body", c["attachment_drift"], ATTACHMENT_DRIFT,
                     "mm", 1e3)
            uncounted = [self.frames[k] for k, v in enumerate(c["self_intersections"]) if v < 0]
            if uncounted:
                lines.append(f"QA: cloth {name!r} self-intersections not counted at {len(uncounted)} frame(s) "
                             f"from frame {uncounted[0]}: too crumpled to count within the work budget "
                             f"(2e8 candidate pairs); see {sidecar}")
        over("substeps at the solver's cap", self.figures["substeps"], self.thresholds["substeps"], "", 1)
        over("cloth fallbacks (steps held still, bodies let through the cloth)", self.figures["cloth_fallbacks"],
             self.thresholds["cloth_fallbacks"], "", 1)
        if self.joint_names:
            who = self.figures["joint_error_joint"]
            over("joint error (gap between a joint's frames)", self.figures["joint_error"], JOINT_ERROR, "mm", 1e3,
                 lambda k: f" ({who[k]})" if who[k] else "")
        if self.motion is not None:
            self._motion_warnings(over)
        return lines

    def _motion_warnings(self, over) -> None:
        f, t = self.figures, self.thresholds
        over("energy gained without a source (the solver made it up: check inertia, add substeps)",
             f["energy_gain"], t["energy_gain"], "J", 1)
        stopped, fastest = f["unexplained_stop_body"], f["imparted_speed_body"]
        over("a body stopped in mid-air, clear of everything (add substeps)", f["unexplained_stop"],
             t["unexplained_stop"], "m/s", 1, lambda k: f" ({stopped[k]})" if stopped[k] else "")
        over("speed beyond what the start and gravity give (a keyed body launched it: check its keys)",
             f["imparted_speed"], t["imparted_speed"], "m/s", 1, lambda k: f" ({fastest[k]})" if fastest[k] else "")

    def layer_summary(self) -> dict[str, Any]:
        """What goes into the cache's customLayerData["simbake"]["qa"]: worst values and frames."""
        out: dict[str, Any] = {"sidecar_version": QA_VERSION}
        summary = self.summary()
        for name, s in summary.items():
            if name == "wall_seconds":
                continue  # differs run to run: the cache must not (same scene, same bytes)
            out[name] = {"worst": s["worst"], "frame": s["frame"]}
            if s["first_over"] is not None:
                out[name]["first_over"] = s["first_over"]
        out["warnings"] = sum(1 for s in summary.values() if s["first_over"] is not None)
        return out

    def as_dict(self, cache: Path, profile: dict[str, float], cache_sha256: str = "") -> dict[str, Any]:
        sidecar = qa_path(cache)
        return {
            "simbake_qa": QA_VERSION,
            "cache": cache.name,
            "cache_sha256": cache_sha256,
            "scene": {"path": str(self.scene.path), "sha256": self.scene.hash(),
                      "settings": _plain(self.scene)},
            "thresholds": self.thresholds,
            "frames": self.frames,
            "time": [(f - self.scene.start_frame) / self.scene.fps for f in self.frames],
            "figures": self.figures,
            "cloths": self.cloths,
            "summary": self.summary(),
            "warnings": self.warnings(sidecar.name),
            "profile": dict(profile),
        }

    def write(self, cache: Path, profile: dict[str, float], outputs=None) -> Path:
        """Writes the sidecar beside the cache (whole or not at all); returns its path. With
        `outputs` (simbake.outputs.Outputs, where the cache is staged) it is staged there too."""
        path = qa_path(cache)
        staged = outputs.staged(cache) if outputs is not None else None
        digest = sha256_of(staged if staged is not None else cache)
        data = self.as_dict(cache, profile, digest)
        text = _dumps(data)

        def write(tmp: str) -> None:
            Path(tmp).write_text(text + "\n")

        if outputs is not None:
            outputs.write(path, write)
        else:
            write_atomically(path, write)
        return path


def _dumps(data: dict[str, Any]) -> str:
    """The sidecar's text: indented down to each figure, whose values per frame (and the
    scene's settings, a line for every body of a pile) go on one line each. Indented JSON is
    written by Python's slow encoder, compact JSON by its fast one."""
    bulky = [(data["scene"], "settings"), (data, "frames"), (data, "time")]
    bulky += [(data["figures"], name) for name in data["figures"]]
    bulky += [(figures, name) for figures in data["cloths"].values() for name in figures]
    values = []
    for k, (owner, key) in enumerate(bulky):
        values.append(owner[key])
        owner[key] = f"{_SETTINGS}:{k}"
    text = json.dumps(data, indent=1, allow_nan=False)
    for (owner, key), value in zip(bulky, values):
        owner[key] = value
    parts = text.split(f'"{_SETTINGS}:')
    for k in range(1, len(parts)):
        index, _, rest = parts[k].partition('"')
        parts[k] = json.dumps(values[int(index)], allow_nan=False) + rest
    return "".join(parts)


def load_qa(cache_or_sidecar: str | Path) -> dict[str, Any]:
    """The QA data of a cache (given the cache or its sidecar)."""
    path = Path(cache_or_sidecar)
    if not path.name.endswith(".qa.json"):
        path = qa_path(path)
    return json.loads(path.read_text())


def _show(value: float, unit: str, scale: float) -> str:
    shown = value * scale
    text = f"{shown:.3g}" if isinstance(shown, float) and not float(shown).is_integer() else f"{int(shown)}"
    return f"{text}%" if unit == "%" else f"{text} {unit}".strip()


def _plain(value: Any) -> Any:
    """Scene settings as JSON: dataclasses as dicts of their fields (dataclasses.asdict's
    without its deep copies), paths as strings, tuples as lists, non-finite floats as strings."""
    kind = type(value)
    if kind is float:
        return value if math.isfinite(value) else str(value)
    if kind in _SCALARS or value is None:
        return value
    if kind is list or kind is tuple:
        return [_plain(v) for v in value]
    names = _FIELDS.get(kind)
    if names is None and dataclasses.is_dataclass(value) and not isinstance(value, type):
        names = _FIELDS[kind] = tuple(f.name for f in dataclasses.fields(value))
    if names is not None:
        return {name: _plain(getattr(value, name)) for name in names}
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    if hasattr(value, "shape") and hasattr(value, "dtype"):  # an inline mesh (a USD shot's)
        return f"array of shape {list(value.shape)}"
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


_FIELDS: dict[type, tuple[str, ...]] = {}  # (_plain's field names of each dataclass type)
