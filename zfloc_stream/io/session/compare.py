"""Compare what a session logged for a frame with what a replay produced.

Two kinds of facts, two rules:

- decisions are compared exactly: the frame index, status, skip reasons (frame and round), whether a pose /
  covariance / alignment exists, the number of hypotheses (status, /zfloc/hypotheses),
  their order (hypotheses[0] is the reported mode), message timestamps and frame ids,
  the BEV grid's size; any string, integer, boolean or null.
- numbers (floats: poses, covariances, alignments, scores, weights, BEV log-odds and
  origin) are compared within a Tolerance: |a - b| <= atol + rtol * max(|a|, |b|); NaN
  only matches NaN and infinity only itself. BEV log-odds are float32, so there the
  relative tolerance is at least two float32 ulps. Tolerance.exact compares them bit
  for bit instead.

Across machines floating point may differ in the last bits (numpy's SIMD kernels and
BLAS pick code paths by CPU); decisions must not. The largest deviation seen on each
topic is kept, so a replay can say how close it came.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

import numpy as np

from ...settings.loading import ReplaySettings
from . import schemas as S

FLOAT32_RTOL = 2 * float(np.finfo(np.float32).eps)  # BEV log-odds are stored as float32


@dataclass(frozen=True)
class Tolerance:
    rtol: float = ReplaySettings().rtol  # defaults: the replay settings'
    atol: float = ReplaySettings().atol
    exact: bool = False  # bit for bit (the recording machine)

    def __str__(self) -> str:
        return "bit for bit" if self.exact else f"rtol {self.rtol:g} + atol {self.atol:g}"


EXACT = Tolerance(0.0, 0.0, exact=True)


@dataclass(frozen=True)
class Divergence:
    frame: int
    topic: str
    field: str
    logged: object
    replayed: object
    note: str = ""  # e.g. how far a number is beyond the tolerance

    def __str__(self) -> str:
        text = f"frame {self.frame}, {self.topic}: {self.field}: logged {self.logged!r}, replay {self.replayed!r}"
        return f"{text} ({self.note})" if self.note else text


@dataclass
class Deviation:
    """The largest numeric deviation seen on one topic: the one closest to its tolerance
    (the largest relative one when comparing bit for bit)."""

    abs: float = 0.0
    rel: float = 0.0  # |a - b| / max(|a|, |b|)
    frame: int | None = None
    field: str = ""
    values: int = 0  # numbers compared
    _rank: float = 0.0

    def see(self, frame: int, name: str, diff: float, scale: float, allowed: float = 0.0) -> None:
        rel = diff / scale if scale > 0 else 0.0
        rank = diff / allowed if allowed > 0 else rel
        if diff > 0 and (rank, diff) > (self._rank, self.abs):
            self.abs, self.rel, self.frame, self.field, self._rank = diff, rel, frame, name, rank

    def __str__(self) -> str:
        if self.abs == 0:
            return f"0 (bit-identical, {self.values} numbers)"
        return f"{self.abs:.3g} (relative {self.rel:.3g}) at frame {self.frame}, {self.field} ({self.values} numbers)"


@dataclass
class Comparison:
    """Compares one frame's topics at a time and keeps the per-topic deviations."""

    tolerance: Tolerance = EXACT
    deviations: dict[str, Deviation] = field(default_factory=dict)

    def frame(self, index: int, pairs: list[tuple[str, object, object]]) -> Divergence | None:
        """pairs: (topic, logged, replayed) for one frame. Decisions are checked on every
        topic before numbers, so a changed decision is reported as such."""
        flat = [(topic, _flatten(a), _flatten(b)) for topic, a, b in pairs]
        for topic, a, b in flat:
            diff = _decision_difference(a, b)
            if diff is not None:
                return Divergence(index, topic, *diff)
        for topic, a, b in flat:
            diff = self._mode_order(index, topic, a, b)
            if diff is not None:
                return diff
        for topic, a, b in flat:
            diff = self._numbers(index, topic, a, b)
            if diff is not None:
                return diff
        return None

    def _numbers(self, index: int, topic: str, a: dict, b: dict) -> Divergence | None:
        dev = self.deviations.setdefault(topic, Deviation())
        tol = self.tolerance
        for key in sorted(a):
            va, vb = a[key], b[key]
            if isinstance(va, np.ndarray):
                diff = self._arrays(index, topic, key, va, vb, dev)
                if diff is not None:
                    return diff
                continue
            if not isinstance(va, float):
                continue
            dev.values += 1
            if math.isnan(va) and math.isnan(vb):
                continue
            if tol.exact or not (math.isfinite(va) and math.isfinite(vb)):
                if va != vb:
                    return Divergence(index, topic, key, va, vb, "" if tol.exact else "not finite on one side")
                if math.isfinite(va):
                    dev.see(index, key, abs(va - vb), max(abs(va), abs(vb)))
                continue
            diff, scale = abs(va - vb), max(abs(va), abs(vb))
            allowed = tol.atol + tol.rtol * scale
            dev.see(index, key, diff, scale, allowed)
            if diff > allowed:
                return Divergence(index, topic, key, va, vb, f"|difference| {diff:.3g} > tolerance {allowed:.3g}")
        return None

    def _arrays(self, index: int, topic: str, key: str, a: np.ndarray, b: np.ndarray, dev: Deviation) -> Divergence | None:
        x, y = a.astype(np.float64), b.astype(np.float64)
        dev.values += x.size
        both_nan = np.isnan(x) & np.isnan(y)
        diff = np.where(both_nan, 0.0, np.abs(x - y))
        diff = np.where(np.isnan(diff) | np.isinf(diff), np.where(x == y, 0.0, np.inf), diff)
        scale = np.where(np.isfinite(x) & np.isfinite(y), np.maximum(np.abs(x), np.abs(y)), 0.0)
        rtol = max(self.tolerance.rtol, FLOAT32_RTOL) if a.dtype == np.float32 else self.tolerance.rtol
        allowed = self.tolerance.atol + rtol * scale
        if diff.size:
            worst = int(np.argmax(diff / np.maximum(allowed, np.finfo(float).tiny)))
            dev.see(index, f"{key}[{worst}]", float(diff.flat[worst]), float(scale.flat[worst]), float(allowed.flat[worst]))
        if self.tolerance.exact:
            bad = np.flatnonzero(~((x == y) | both_nan))
        else:
            bad = np.flatnonzero(diff > allowed)
        if bad.size:
            i = int(bad[0])
            return Divergence(index, topic, f"{key}[{i}]", float(x.flat[i]), float(y.flat[i]), f"{bad.size} of {x.size} values differ")
        return None

    def _mode_order(self, index: int, topic: str, a: dict, b: dict) -> Divergence | None:
        """The reported mode and the order of the alternatives are decisions: a replayed
        hypothesis that matches another logged one (within the tolerance) is a swap."""
        n = a.get("hypotheses.len")
        if topic != S.TOPIC_STATUS or not n:
            return None

        def numbers(flat: dict, i: int) -> list:
            prefix = f"hypotheses.[{i}]."
            return [flat[k] for k in sorted(flat) if k.startswith(prefix) and isinstance(flat[k], float)]

        logged = [numbers(a, i) for i in range(n)]
        order = []  # the logged index each replayed hypothesis matches (None: none)
        for i in range(n):
            mine = numbers(b, i)
            if self._close(logged[i], mine):
                order.append(i)
            else:
                order.append(next((j for j in range(n) if self._close(logged[j], mine)), None))
        if any(j is not None and j != i for i, j in enumerate(order)):
            return Divergence(index, topic, "hypotheses order (hypotheses[0] is the reported mode)", list(range(n)),
                              [-1 if j is None else j for j in order], "a replayed mode matches another logged mode")
        return None

    def _close(self, xs: list, ys: list) -> bool:
        tol = self.tolerance
        for x, y in zip(xs, ys, strict=True):
            if math.isnan(x) and math.isnan(y):
                continue
            if tol.exact or not (math.isfinite(x) and math.isfinite(y)):
                if x != y:
                    return False
            elif abs(x - y) > tol.atol + tol.rtol * max(abs(x), abs(y)):
                return False
        return True


# --- flattening -------------------------------------------------------------------------------
def comparable_status(status: dict) -> dict:
    """A status without its wall-clock timings; the JSON round trip makes both sides alike."""
    return {k: v for k, v in json.loads(S.encode_status(status)).items() if k not in S.MEASURED_STATUS_KEYS}


def comparable_grid(grid: S.BevGrid) -> dict:
    """A BEV grid as shape (exact), origin and resolution (numbers) and values (array)."""
    values = np.asarray(grid.values)
    return {"shape": list(values.shape), "origin": [float(v) for v in np.asarray(grid.origin).ravel()],
            "resolution": float(grid.resolution), "values": values}


def _is_repeated(desc) -> bool:
    # protobuf >= 5 spells it is_repeated; older releases only have label
    flag = getattr(desc, "is_repeated", None)
    return bool(flag) if flag is not None else desc.label == desc.LABEL_REPEATED


def _flatten(value, prefix: str = "") -> dict[str, object]:
    """Nested protobuf messages / dicts / lists as {dotted.path: leaf} (arrays stay whole)."""
    if hasattr(value, "ListFields"):
        out: dict[str, object] = {}
        for desc in value.DESCRIPTOR.fields:  # every field, set or not: a missing one is 0
            v = getattr(value, desc.name)
            key = f"{prefix}{desc.name}"
            if _is_repeated(desc):
                out[key + ".len"] = len(v)
                for i, item in enumerate(v):
                    out.update(_flatten(item, f"{key}[{i}]."))
            elif desc.message_type is not None:
                out.update(_flatten(v, key + "."))
            else:
                out[key] = v
        return out
    if isinstance(value, dict):
        out = {}
        for k in sorted(value):
            out.update(_flatten(value[k], f"{prefix}{k}."))
        return out
    if isinstance(value, list):
        out = {f"{prefix}len": len(value)}
        for i, item in enumerate(value):
            out.update(_flatten(item, f"{prefix}[{i}]."))
        return out
    return {prefix.rstrip("."): value}


def _describe(v) -> object:
    if isinstance(v, bytes):
        return f"<{len(v)} bytes>"
    if isinstance(v, np.ndarray):
        return f"<{v.dtype} array {v.shape}>"
    return v


def _decision_difference(a: dict, b: dict) -> tuple[str, object, object] | None:
    """The first key whose presence, type or non-float value differs."""
    for key in sorted(a.keys() | b.keys()):
        va, vb = a.get(key, "<absent>"), b.get(key, "<absent>")
        if type(va) is not type(vb):
            return key, _describe(va), _describe(vb)
        if isinstance(va, np.ndarray):
            if va.shape != vb.shape or va.dtype != vb.dtype:
                return key, _describe(va), _describe(vb)
        elif not isinstance(va, float) and va != vb:
            return key, _describe(va), _describe(vb)
    return None
