"""Settings of the tracker: the filter bank over alignments and its policy (tracking/filter_bank.py, tracking/policy.py)."""

from __future__ import annotations

from pydantic import Field

from .base import Section


class TrackingSettings(Section):
    """Filter bank over the alignment, state anchored at the sensor (see tracking/filter_bank.py)."""

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
    gate_chi2: float = Field(13.28, gt=0, le=1e6)  # association gate: Mahalanobis^2 of a hypothesis to a mode, chi2(4 dof) at 99%
    # weights = softmax(weight_gain * running score); running score = EMA of fresh scores.
    # Every decision below compares modes with each other or with the round's best
    # hypothesis: score levels differ between map styles (0.8+ on clean plans, -0.5..0.45
    # on maps built from other passes), score differences mean the same everywhere.
    score_smoothing: float = Field(0.3, ge=0, le=1)  # EMA factor of a fresh score (0.3: a round's score is 30% of the running score)
    # a mode nothing matched this round: fresh = running score - this. With the defaults an
    # unseen mode's running score drops 0.15 per round against a rival that keeps its own,
    # its weight 9.5x (exp(15 * 0.15)) per round: under prune_weight (0.001) after about 4
    # unseen rounds from an even start
    unobserved_penalty: float = Field(0.5, ge=0, le=10)
    # weights = softmax(this * running score): 15 makes a running-score lead of 0.046 a
    # weight ratio of 2 (ln 2 / 15), of 0.15 a ratio of 9.5
    weight_gain: float = Field(15.0, ge=0, le=1000)
    # births, pruning, merging
    birth_score_gap: float = Field(0.15, ge=0, le=10)  # an unmatched hypothesis within this of the round's best starts a mode (the best always does)
    # an unmatched hypothesis that started no mode but scored within this of the round's best
    # is scored again in the next round while no mode was tracked yet (policy.revisit_rule): a round's random draw
    # need not find a place twice for its second look to count (camera aces 390 #50 on a
    # plan: the truth 0.165 behind a flipped corridor in round 1, not drawn in round 2, the
    # flipped one confirmed alone: `tracking` 14-23 m off)
    revisit_score_gap: float = Field(0.3, ge=0, le=10)
    prune_weight: float = Field(0.001, ge=0, lt=1)  # a mode under this share of the weight leaves the bank
    max_modes: int = Field(8, ge=1, le=1000)  # at most this many modes, the heaviest kept
    merge_translation: float = Field(0.3, ge=0, le=100)  # m, implied sensor positions closer than this...
    merge_angle_deg: float = Field(5.0, ge=0, le=180)  # ...and headings closer than this...
    merge_log_scale: float = Field(0.05, ge=0, le=10)  # ...and log scales closer than this: one mode
    # status
    confirm_rounds: int = Field(2, ge=1, le=1000)  # rounds a mode was found near the top (within confirm_score_gap) before it can be tracked
    confirm_score_gap: float = Field(0.1, ge=0, le=10)  # "near the top": a fresh score within this of the round's best
    # a second confirmed mode with weight >= this * best: ambiguous. At weight_gain 15, 0.5
    # means running scores within 0.046 (ln(1 / 0.5) / 15)
    ambiguity_ratio: float = Field(0.5, gt=0, le=1)
    # tracking needs the best mode's share of the tracker's weight above this: 0.9 = its rivals
    # together hold under a tenth of it. At 0.5 (more than all rivals together) 2.9% of the
    # real laser windows' tracking frames were 1 m+ off (16 of 200 windows, rivals holding
    # 30-47%); at 0.9 0.4%, camera 0.2%, the same poses (docs/status.md).
    dominance_weight: float = Field(0.9, ge=0, lt=1)
    lost_score_gap: float = Field(0.1, ge=0, le=10)  # a mode collapses in a round when a rival scores this much more (or nothing matches it)...
    lost_rounds: int = Field(3, ge=1, le=1000)  # ...this many rounds in a row: the tracked one is lost (the rival, if any, takes over), another leaves the bank
    # after a loss a mode needs this many hits (at least confirm_rounds) before it is tracked:
    # the evidence it took to drop a track is what it takes to trust the next one
    confirm_rounds_after_loss: int = Field(3, ge=1, le=1000)
    # the tracked mode is reported (hysteresis) unless the heaviest confirmed mode is another
    # one found near the top in this many rounds: then that one, and the tracked mode is lost
    rival_established_rounds: int = Field(3, ge=1, le=1000)
    # nothing tracked: a mode whose running score leads the heaviest confirmed mode's by more
    # than this is reported while it earns confirmation (scores, as lost_score_gap)
    newcomer_score_gap: float = Field(0.1, ge=0, le=10)
    # a frame whose reported pose at the sensor moved by more than this Mahalanobis^2 (mode
    # pose covariance + one measurement; chi2(3 dof) 13.28 is beyond 99.5%) is not `tracking`
    pose_jump_chi2: float = Field(13.28, gt=0, le=1e6)
    # the map's fit (policy.map_fit): a ramp in the share of the latest BEV's wall points
    # within localizer.monitor_distance of a plan wall under the reported alignment, 1/2 at
    # this share, 0 at this minus confidence_share_band, 1 at this plus it. Estimate.confidence
    # is weight x confirmation x fit; a frame is `tracking` only while weight x fit exceeds
    # dominance_weight (MAP_UNEXPLAINED; with weight 1: a share above 0.67). Shared camera
    # sessions: on their own maps every frame >= 0.61; on other buildings' maps tracks started
    # at 0.46 (before this rule), laser windows at 0.575-0.62. Band 0: a step at this share
    min_explained_share: float = Field(0.55, ge=0, le=1)
    # 0.15: the narrowest band at which no laser frame on another building's map reached
    # confidence 0.9 (the windows it was chosen on; on the others 10 of 26,400 frames did,
    # look-alike corridors; camera windows and sessions, scenes: none)
    confidence_share_band: float = Field(0.15, ge=0, le=1)
    confident_rounds: int = Field(5, ge=1, le=10_000)  # rounds of tracking one mode before confidently_tracking
    # odometry jump (policy.odometry_jumped): a step between two fused frames longer
    # than odometry_jump_min_step + odometry_jump_factor x the longest of the last
    # odometry_jump_window steps (or a turn likewise), whose wall hits the BEV does not
    # explain, restarts the map and the hypotheses (status lost). 0 frames: never judged.
    # Not explained: fewer than localizer.monitor_min_points (or odometry_jump_min_known_share
    # of the frame's wall hits) on cells older frames saw, or at least
    # odometry_jump_contradiction of them where those frames saw open space. Measured on
    # frames past the gate: ordinary frames of the shared Carmen windows (1-3.3 m and up to
    # 82 deg a frame, glass and clutter) contradict up to 0.31 and land >= 0.49 (laser) /
    # 0.73 (camera) of their hits on seen cells; built-in walks >= 0.43 on seen cells. A
    # 1 m / 10 deg / x1 gate with 0.15 let Carmen turns restart the map (SR@1m 69% -> 64%).
    odometry_jump_window: int = Field(10, ge=0, le=10_000)  # frames of recent motion it is compared with (0: off)
    odometry_jump_min_step: float = Field(1.5, ge=0, le=1e6)  # m
    odometry_jump_min_turn_deg: float = Field(15.0, ge=0, le=360)
    odometry_jump_factor: float = Field(1.5, ge=0, le=1e6)
    odometry_jump_contradiction: float = Field(0.6, ge=0, le=1)
    odometry_jump_min_known_share: float = Field(0.25, ge=0, le=1)
