"""Settings of the tracker: the filter bank over alignments and its policy (tracking.py)."""

from __future__ import annotations

from pydantic import Field

from .base import Section


class TrackingSettings(Section):
    """Filter bank over the alignment, state anchored at the sensor (see tracking.py)."""

    # random-walk drift per round: variance grows with frames elapsed and metres travelled
    process_translation_std_per_frame: float = Field(0.01, ge=0, le=100)  # m per sqrt(frame), implied sensor position
    process_angle_deg_per_frame: float = Field(0.1, ge=0, le=180)  # deg per sqrt(frame)
    process_log_scale_per_frame: float = Field(0.001, ge=0, le=10)  # per sqrt(frame)
    process_translation_std_per_m: float = Field(0.05, ge=0, le=100)  # m per sqrt(m travelled)
    process_angle_deg_per_m: float = Field(1.0, ge=0, le=180)  # deg per sqrt(m travelled)
    process_log_scale_per_m: float = Field(0.01, ge=0, le=10)  # per sqrt(m travelled)
    # one refined RANSAC hypothesis, expressed at the sensor (also a new mode's covariance)
    measurement_translation_std: float = Field(0.15, gt=0, le=100)  # m
    measurement_angle_deg: float = Field(2.0, gt=0, le=180)
    measurement_log_scale: float = Field(0.02, gt=0, le=10)
    gate_chi2: float = Field(13.28, gt=0, le=1e6)  # Mahalanobis^2 gate, chi2(4 dof) at 99%
    # weights = softmax(weight_gain * running score); running score = EMA of fresh scores.
    # Every decision below compares modes with each other or with the round's best
    # hypothesis: score levels differ between map styles (0.8+ on clean plans, -0.5..0.45
    # on maps built from other passes), score differences mean the same everywhere.
    score_smoothing: float = Field(0.3, ge=0, le=1)  # EMA factor of a fresh score
    unobserved_penalty: float = Field(0.5, ge=0, le=10)  # a mode nothing matched this round: fresh = running score - this
    weight_gain: float = Field(15.0, ge=0, le=1000)
    # births, pruning, merging
    birth_score_gap: float = Field(0.15, ge=0, le=10)  # an unmatched hypothesis within this of the round's best starts a mode (the best always does)
    prune_weight: float = Field(0.001, ge=0, lt=1)
    max_modes: int = Field(8, ge=1, le=1000)
    merge_translation: float = Field(0.3, ge=0, le=100)  # m, implied sensor positions closer than this...
    merge_angle_deg: float = Field(5.0, ge=0, le=180)  # ...and headings closer than this...
    merge_log_scale: float = Field(0.05, ge=0, le=10)  # ...and log scales closer than this: one mode
    # status
    confirm_rounds: int = Field(2, ge=1, le=1000)  # rounds a mode was found near the top (within confirm_score_gap) before it can be tracked
    confirm_score_gap: float = Field(0.1, ge=0, le=10)  # "near the top": a fresh score within this of the round's best
    ambiguity_ratio: float = Field(0.5, gt=0, le=1)  # a second confirmed mode with weight >= this * best: ambiguous
    # tracking needs the best mode's share of the tracker's weight above this: 0.9 = its rivals
    # together hold under a tenth of it. At 0.5 (more than all rivals together) 2.9% of the
    # real laser windows' tracking frames were 1 m+ off (16 of 200 windows, rivals holding
    # 30-47%); at 0.9 0.4%, camera 0.2%, the same poses (docs/status.md).
    dominance_weight: float = Field(0.9, ge=0, lt=1)
    lost_score_gap: float = Field(0.1, ge=0, le=10)  # the tracked mode collapses in a round when a rival scores this much more (or nothing matches it)...
    lost_rounds: int = Field(3, ge=1, le=1000)  # ...this many rounds in a row: lost (the rival, if any, takes over)
    confident_rounds: int = Field(5, ge=1, le=10_000)  # rounds of tracking one mode before confidently_tracking
