"""Ours in hindsight: every track fragment of a stretch assigned to the wearers at once, without labels.

The camera-identity paper (hub/identity/paper/) matches a fragment's speed to a wearer's vertical
acceleration through a regression fitted on labelled data, then assigns people one at a time in
every order (n!). Here the same two features (`fragment_errors`: the mean absolute error Mae between
the acceleration a fragment's speed predicts and the one a wearer's waist measured) feed one global
choice, and the regression is learnt from the stretch itself:

- **Gain.** Wearer p on fragment k is worth L x (Ave + SD - Mae): the seconds they share, times how
  much better than a lost stretch the fit is (the paper charges a lost stretch Mae = Ave + SD, its
  virtual fragment). A pair that fits worse than losing the wearer is never taken.
- **One choice for everyone** (`assign`): the largest total gain such that a fragment holds at most
  one wearer and a wearer at most one fragment at any moment (fragments may overlap by the paper's
  tolerance of 2 frames, a tracker's hand-over). Each wearer's fragments are intervals, so "one at
  a time" is one constraint per interval start (the cliques of an interval graph). A mixed-integer
  program, solved by HiGHS (scipy.optimize.milp); its LP relaxation has been integral wherever measured
  (`HindsightResult.relaxation_gap` says by how much it was not).
- **No labels** (`identify_hindsight`): start from a loose population line, assign, refit the line
  and Ave / SD on the pairs just assigned, and repeat until the assignment stops changing (hard
  expectation-maximisation). Two things keep that loop from feeding on its own mistakes, each
  seen on room worlds 1-10 (docs/identity.md): the line is refitted as the reduced major axis (a
  least-squares slope flattens with every wrong pair taken, a flatter line takes more wrong pairs,
  and the fit collapses to "everyone still on any track") and never below the slope walking allows;
  and of the assignments on the way, the one returned is the likeliest against nobody's (a pair's
  |error| exponential with mean Ave against the mean over every pair), a score that, unlike the
  gains, means the same whatever line made it. The start is the live engine's speed prior
  (hub/identity/cues.py `SpeedModel`: 6 m/s per g above 0.03 g) as the paper's line.

Pure numpy / scipy, no I/O. Bad input raises ValueError naming the value (from the paper's modules).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Mapping

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import csr_matrix

from hub.identity.paper.features import PaperModel
from hub.identity.paper.fragments import Fragments, TrackArrays, frame_period_s, on_frame_grid, split_fragments
from hub.identity.paper.search import OVERLAP_TOLERANCE_FRAMES, fragment_errors

# The live engine's prior line (SpeedModel: speed = 6 m/s per g x (activity - 0.03 g)) as vertical
# acceleration on speed; Ave and SD loose (a lost stretch costs 0.06 g, twice the activity floor).
PRIOR = PaperModel(slope_g_per_mps=1.0 / 6.0, intercept_g=0.03, ave_abs_error_g=0.03, sd_abs_error_g=0.03)
MAX_ITERATIONS = 10
# Walking moves the pelvis up and down 3-5 cm a stride at ~2 steps/s: about 0.2 g of mean |vertical
# acceleration| at 1.3 m/s, some 0.15 g per m/s. A line much flatter fits "everyone still" to any track,
# an assignment that feeds itself: the fit may not go below this.
MIN_SLOPE_G_PER_MPS = 0.06
MIN_FIT_FRAMES = 50  # a refit on fewer assigned frames (2.5 s at 20 fps) keeps the previous line
TIME_LIMIT_S = 10.0  # per solve; HiGHS returns its best assignment so far when it is reached


@dataclass(frozen=True)
class HindsightResult:
    """Who held which fragment, the line learnt, and how the search went."""

    people: tuple[str, ...]
    fragments: Fragments
    chosen: tuple[tuple[int, int], ...]  # (person index, fragment index)
    model: PaperModel  # the line and Ave / SD the assignment was made with
    iterations: int  # the assignment returned was the iterations-th
    converged: bool  # the assignment stopped changing before MAX_ITERATIONS
    total_gain: float
    relaxation_gap: float  # LP bound minus the integer total, as a share of the total (0: the LP was integral)
    likelihood_ratio: float  # of the assignment against nobody's, summed over its pairs' seconds

    def assignment(self, frame_ns: np.ndarray) -> dict[str, np.ndarray]:
        """Per person, the track id held at each of `frame_ns` (the frame grid the tracks were on); 0: none.
        Where two of a person's fragments overlap (the tolerance), the later one holds the frame."""
        frames = np.asarray(frame_ns, dtype=np.int64)
        out = {name: np.zeros(len(frames), dtype=np.int64) for name in self.people}
        f = self.fragments
        for p, k in sorted(self.chosen, key=lambda pk: f.start_frame[pk[1]]):
            out[self.people[p]][f.start_frame[k]:f.end_frame[k] + 1] = f.track_id[k]
        return out


def gains(model: PaperModel, fragments: Fragments, verticals: np.ndarray, people: tuple[str, ...],
          frame_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(people, fragments) twice, 0 where they share no frame: the gain L x (Ave + SD - Mae) the assignment
    maximises, and the log-likelihood ratio (per second of the pair) that scores a whole assignment."""
    errors = fragment_errors(fragments, verticals, people, model, frame_s)
    known = np.isfinite(errors.mae_g)
    lost = model.ave_abs_error_g + model.sd_abs_error_g
    gain = np.where(known, errors.length_s * (lost - np.where(known, errors.mae_g, 0.0)), 0.0)
    # A right pair's |error| taken as exponential with mean Ave, anyone else's with the mean over every pair
    # (in a crowd nearly all wrong). Unlike the gain, the ratio means the same whatever line made it.
    right = max(model.ave_abs_error_g, 1e-6)
    background = float(np.average(errors.mae_g[known], weights=errors.frames[known])) if known.any() else right
    per_s = np.log(background / right) - np.where(known, errors.mae_g, 0.0) * (1.0 / right - 1.0 / background)
    return gain, np.where(known, errors.length_s * per_s, 0.0)


def assign(gain: np.ndarray, start_frame: np.ndarray, end_frame: np.ndarray,
           overlap_tolerance_frames: int = OVERLAP_TOLERANCE_FRAMES) -> tuple[list[tuple[int, int]], float, float]:
    """The pairs (person, fragment) of largest total gain, each fragment to one person and each person on
    one fragment at a time; (pairs, total, relaxation gap). Only pairs of positive gain are candidates."""
    people, count = np.nonzero(gain > 0)
    if not len(people):
        return [], 0.0, 0.0
    start = np.asarray(start_frame)[count]
    # a hand-over's overlap is allowed: each interval ends `tolerance` frames early (but keeps one frame)
    end = np.maximum(np.asarray(end_frame)[count] - overlap_tolerance_frames, start)
    rows: list[np.ndarray] = []
    for k in np.unique(count):  # a fragment holds one person
        members = np.flatnonzero(count == k)
        if len(members) > 1:
            rows.append(members)
    for p in np.unique(people):  # a person is on one fragment at a time: one row per distinct clique
        mine = np.flatnonzero(people == p)
        seen: set[tuple[int, ...]] = set()
        for t0 in np.unique(start[mine]):
            active = tuple(mine[(start[mine] <= t0) & (end[mine] >= t0)].tolist())
            if len(active) > 1 and active not in seen:
                seen.add(active)
                rows.append(np.array(active))
    weights = gain[people, count]
    constraints = []
    if rows:
        indptr = np.cumsum([0] + [len(r) for r in rows])
        matrix = csr_matrix((np.ones(indptr[-1]), np.concatenate(rows), indptr), shape=(len(rows), len(weights)))
        constraints = [LinearConstraint(matrix, -np.inf, 1.0)]
    bounds = Bounds(0.0, 1.0)
    solved = milp(-weights, constraints=constraints, integrality=np.ones(len(weights)), bounds=bounds,
                  options={"time_limit": TIME_LIMIT_S})
    if solved.x is None:
        raise RuntimeError(f"hindsight assignment: HiGHS found no solution ({solved.message})")
    take = solved.x > 0.5
    total = float(weights[take].sum())
    relaxed = milp(-weights, constraints=constraints, bounds=bounds)
    bound = -float(relaxed.fun) if relaxed.x is not None else total
    return list(zip(people[take].tolist(), count[take].tolist())), total, (bound - total) / max(total, 1e-12)


def refit(chosen: list[tuple[int, int]], fragments: Fragments, verticals: np.ndarray,
          previous: PaperModel) -> PaperModel:
    """The line and Ave / SD of eq. 1 over the frames of the pairs taken; `previous` if too few or too flat."""
    label = np.repeat(np.arange(len(fragments.track_id)), np.diff(fragments.offsets))
    speeds, values = [], []
    for p, k in chosen:
        mine = label == k
        speeds.append(fragments.speed_mps[mine])
        values.append(verticals[p, fragments.frame_index[mine]])
    if not speeds:
        return previous
    s, v = np.concatenate(speeds), np.concatenate(values)
    ok = np.isfinite(s) & np.isfinite(v)
    if ok.sum() < MIN_FIT_FRAMES or np.ptp(s[ok]) == 0:
        return previous
    # Reduced major axis, not least squares: a least-squares slope shrinks by the share of the pairs that are
    # wrong (and by the speed's own noise), the next assignment takes more of the still and wrong pairs a
    # flatter line fits, and the fit collapses; the ratio of the spreads does not shrink with either.
    slope = max(float(np.std(v[ok]) / np.std(s[ok])), MIN_SLOPE_G_PER_MPS)
    intercept = float(np.mean(v[ok]) - slope * np.mean(s[ok]))
    errors = np.abs(v[ok] - (slope * s[ok] + intercept))
    return PaperModel(float(slope), float(intercept), float(errors.mean()), float(errors.std()),
                      float(np.corrcoef(s[ok], v[ok])[0, 1]), int(ok.sum()), previous.window_s)


def identify_hindsight(tracks: TrackArrays, people: Mapping[str, tuple[np.ndarray, np.ndarray]],
                       prior: PaperModel = PRIOR, max_iterations: int = MAX_ITERATIONS) -> HindsightResult:
    """Assign every fragment of `tracks` at once, the regression learnt on the way.

    people: name -> (time_ns, vertical acceleration in g), as for the paper's `identify`
    (`vertical_acceleration` of each wearer's waist on the venue clock)."""
    if max_iterations < 1:
        raise ValueError(f"max_iterations {max_iterations} must be >= 1")
    fragments = split_fragments(tracks, prior.window_s)
    frames = np.asarray(tracks.frame_ns, dtype=np.int64)
    names = tuple(sorted(people))
    verticals = np.array([on_frame_grid(frames, n, *people[n]) for n in names]).reshape(len(names), len(frames))
    frame_s = frame_period_s(frames) if len(frames) > 1 else 0.05
    model, previous = prior, None
    best: tuple[float, list[tuple[int, int]], PaperModel, float, float, int] | None = None
    converged = False
    for iteration in range(1, max_iterations + 1):
        gain, likelihood = gains(model, fragments, verticals, names, frame_s)
        taken, total, gap = assign(gain, fragments.start_frame, fragments.end_frame)
        score = float(sum(likelihood[p, k] for p, k in taken))
        if best is None or score > best[0]:
            best = (score, taken, model, total, gap, iteration)
        if previous is not None and set(taken) == set(previous):
            converged = True
            break
        previous = taken
        model = refit(taken, fragments, verticals, model)
    score, chosen, model, total, gap, iteration = best
    return HindsightResult(names, fragments, tuple(chosen), model, iteration, converged, total, gap, score)
