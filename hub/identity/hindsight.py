"""Ours in hindsight: every track fragment of a stretch assigned to the wearers at once, without labels.

The camera-identity paper (hub/identity/paper/) matches a fragment's speed to a wearer's vertical
acceleration through a regression fitted on labelled data, then assigns people one at a time in
every order (n!). Here the same two features (the mean absolute error Mae between the acceleration
a fragment's speed predicts and the one a wearer's waist measured) feed one global choice, and the
regression is learnt from the stretch itself. The evidence is `Samples`: one entry per (fragment,
moment), the fragment's speed there and every wearer's vertical acceleration then;
`identify_hindsight` makes them from a session's camera frames (the paper's features),
hub/identity/window.py from the live engine's 0.1 s bins.

- **Gain.** Wearer p on fragment k is worth L x (Ave + SD - Mae): the seconds they share, times how
  much better than a lost stretch the fit is (the paper charges a lost stretch Mae = Ave + SD, its
  virtual fragment). A pair that fits worse than losing the wearer is never taken.
- **One choice for everyone** (`assign`): the largest total gain such that a fragment holds at most
  one wearer and a wearer at most one fragment at any moment (fragments may overlap by the paper's
  tolerance of 2 frames, a tracker's hand-over). Each wearer's fragments are intervals, so "one at
  a time" is one constraint per interval start (the cliques of an interval graph). An integer program
  solved by HiGHS (scipy.optimize.milp): its LP relaxation first, which has been integral wherever
  measured (then it is the answer, in polynomial time), branch and bound where it is not
  (`Solution.relaxation_gap` says by how much the two differed).
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

from dataclasses import dataclass, replace
from typing import Mapping

import numpy as np
from scipy.optimize import Bounds, LinearConstraint, milp
from scipy.sparse import csr_matrix

from hub.identity.paper.features import PaperModel
from hub.identity.paper.fragments import Fragments, TrackArrays, frame_period_s, on_frame_grid, split_fragments
from hub.identity.paper.search import OVERLAP_TOLERANCE_FRAMES

# The live engine's prior line (SpeedModel: speed = 6 m/s per g x (activity - 0.03 g)) as vertical
# acceleration on speed; Ave and SD loose (a lost stretch costs 0.06 g, twice the activity floor).
PRIOR = PaperModel(slope_g_per_mps=1.0 / 6.0, intercept_g=0.03, ave_abs_error_g=0.03, sd_abs_error_g=0.03)
MAX_ITERATIONS = 10
# Walking moves the pelvis up and down 3-5 cm a stride at ~2 steps/s: about 0.2 g of mean |vertical
# acceleration| at 1.3 m/s, some 0.15 g per m/s. A line much flatter fits "everyone still" to any track,
# an assignment that feeds itself: the fit may not go below this.
MIN_SLOPE_G_PER_MPS = 0.06
MIN_FIT_S = 2.5  # a refit on fewer assigned seconds keeps the previous line
TIME_LIMIT_S = 10.0  # per branch and bound; HiGHS returns its best assignment so far when it is reached
INTEGRAL_TOLERANCE = 1e-6  # an LP optimum this close to 0 / 1 everywhere is an assignment
# A second of the live engine's identity on a fragment counts as a second of fit 0.03 g better than a lost
# stretch (chosen on the paper's room seeds 1-5 and 6 / 10 wearers seeds 1-5 from 0.003-0.3: docs/identity.md)
HELD_WEIGHT_G = 0.03


@dataclass(frozen=True)
class Samples:
    """A stretch's evidence, one entry per (fragment, moment); times are frame or bin numbers."""

    label: np.ndarray  # (N,) fragment index
    speed_mps: np.ndarray  # (N,) the fragment's speed there; NaN unknown
    measured_g: np.ndarray  # (P, N) each wearer's vertical acceleration then; NaN unknown
    start: np.ndarray  # (K,) each fragment's first time index
    end: np.ndarray  # (K,) ... and last
    sample_s: float  # seconds per time index


@dataclass(frozen=True)
class Solution:
    """Who held which fragment, the line the choice was made with, and how the search went."""

    chosen: tuple[tuple[int, int], ...]  # (person index, fragment index)
    model: PaperModel
    iterations: int  # the assignment returned was the iterations-th
    converged: bool  # the assignment stopped changing before max_iterations
    total_gain: float
    relaxation_gap: float  # LP bound minus the integer total, as a share of the total (0: the LP was integral)
    likelihood_ratio: float  # of the assignment against nobody's, summed over its pairs' seconds


@dataclass(frozen=True)
class HindsightResult:
    """A session's `Solution` over its camera's fragments, named."""

    people: tuple[str, ...]
    fragments: Fragments
    solution: Solution

    def assignment(self, frame_ns: np.ndarray) -> dict[str, np.ndarray]:
        """Per person, the track id held at each of `frame_ns` (the frame grid the tracks were on); 0: none.
        Where two of a person's fragments overlap (the tolerance), the later one holds the frame."""
        frames = np.asarray(frame_ns, dtype=np.int64)
        out = {name: np.zeros(len(frames), dtype=np.int64) for name in self.people}
        f = self.fragments
        for p, k in sorted(self.solution.chosen, key=lambda pk: f.start_frame[pk[1]]):
            out[self.people[p]][f.start_frame[k]:f.end_frame[k] + 1] = f.track_id[k]
        return out


def gains(model: PaperModel, samples: Samples) -> tuple[np.ndarray, np.ndarray]:
    """(people, fragments) twice, 0 where they share no sample: the gain L x (Ave + SD - Mae) the assignment
    maximises, and the log-likelihood ratio (per second of the pair) that scores a whole assignment."""
    people, count = len(samples.measured_g), len(samples.start)
    error = np.abs(samples.measured_g - model.predict(samples.speed_mps)[None, :])
    valid = np.isfinite(error)
    shared = np.zeros((people, count))
    sums = np.zeros((people, count))
    for p in range(people):
        shared[p] = np.bincount(samples.label, weights=valid[p], minlength=count)
        sums[p] = np.bincount(samples.label, weights=np.where(valid[p], error[p], 0.0), minlength=count)
    known = shared > 0
    mae = np.where(known, sums / np.maximum(shared, 1), 0.0)
    seconds = shared * samples.sample_s
    lost = model.ave_abs_error_g + model.sd_abs_error_g
    gain = np.where(known, seconds * (lost - mae), 0.0)
    # A right pair's |error| taken as exponential with mean Ave, anyone else's with the mean over every pair
    # (in a crowd nearly all wrong). Unlike the gain, the ratio means the same whatever line made it.
    right = max(model.ave_abs_error_g, 1e-6)
    background = float(sums.sum() / shared.sum()) if known.any() else right
    per_s = np.log(background / right) - mae * (1.0 / right - 1.0 / background)
    return gain, np.where(known, seconds * per_s, 0.0)


def assign(gain: np.ndarray, start_frame: np.ndarray, end_frame: np.ndarray,
           overlap_tolerance_frames: int = OVERLAP_TOLERANCE_FRAMES,
           candidates: int | None = None) -> tuple[list[tuple[int, int]], float, float]:
    """The pairs (person, fragment) of largest total gain, each fragment to one person and each person on
    one fragment at a time; (pairs, total, relaxation gap). Only pairs of positive gain are candidates, and
    with `candidates`, only each fragment's that many best people (the program's size in a crowd)."""
    positive = gain > 0
    if candidates is not None and gain.shape[0] > candidates:
        rank = np.argsort(np.argsort(-gain, axis=0), axis=0)  # 0 for a fragment's best person
        positive &= rank < candidates
    people, count = np.nonzero(positive)
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
    # The LP relaxation first (polynomial): where its optimum is integral, as it has been wherever measured,
    # it is the assignment; otherwise branch and bound from it.
    relaxed = milp(-weights, constraints=constraints, bounds=bounds)
    if relaxed.x is None:
        raise RuntimeError(f"hindsight assignment: HiGHS found no solution ({relaxed.message})")
    bound = -float(relaxed.fun)
    solved = relaxed
    if np.any(np.minimum(relaxed.x, 1.0 - relaxed.x) > INTEGRAL_TOLERANCE):
        solved = milp(-weights, constraints=constraints, integrality=np.ones(len(weights)), bounds=bounds,
                      options={"time_limit": TIME_LIMIT_S})
        if solved.x is None:
            raise RuntimeError(f"hindsight assignment: HiGHS found no solution ({solved.message})")
    take = solved.x > 0.5
    total = float(weights[take].sum())
    return list(zip(people[take].tolist(), count[take].tolist())), total, max(bound - total, 0.0) / max(total, 1e-12)


def refit(chosen: list[tuple[int, int]], samples: Samples, previous: PaperModel) -> PaperModel:
    """The line and Ave / SD of eq. 1 over the samples of the pairs taken; `previous` if too few or still."""
    if not chosen:
        return previous
    person = np.full(len(samples.start), -1)
    person[[k for _, k in chosen]] = [p for p, _ in chosen]
    mine = person[samples.label]
    taken = np.flatnonzero(mine >= 0)
    s, v = samples.speed_mps[taken], samples.measured_g[mine[taken], taken]
    ok = np.isfinite(s) & np.isfinite(v)
    if ok.sum() * samples.sample_s < MIN_FIT_S or np.ptp(s[ok]) == 0:
        return previous
    s, v = s[ok], v[ok]
    # Reduced major axis, not least squares: a least-squares slope shrinks by the share of the pairs that are
    # wrong (and by the speed's own noise), the next assignment takes more of the still and wrong pairs a
    # flatter line fits, and the fit collapses; the ratio of the spreads does not shrink with either.
    slope = max(float(np.std(v) / np.std(s)), MIN_SLOPE_G_PER_MPS)
    intercept = float(np.mean(v) - slope * np.mean(s))
    errors = np.abs(v - (slope * s + intercept))
    correlation = float(np.corrcoef(s, v)[0, 1]) if np.ptp(v) > 0 else float("nan")
    return PaperModel(float(slope), float(intercept), float(errors.mean()), float(errors.std()), correlation,
                      len(s), previous.window_s)


def solve(samples: Samples, prior: PaperModel = PRIOR, max_iterations: int = MAX_ITERATIONS,
          overlap_tolerance: int = OVERLAP_TOLERANCE_FRAMES, candidates: int | None = None,
          bonus: np.ndarray | None = None) -> Solution:
    """Assign, refit, repeat from `prior`; the likeliest of the assignments made (see the module's docstring).
    `bonus` (people, fragments) is added to every round's gains: evidence from elsewhere, in the gains' units."""
    if max_iterations < 1:
        raise ValueError(f"max_iterations {max_iterations} must be >= 1")
    model, previous = prior, None
    best: Solution | None = None
    for iteration in range(1, max_iterations + 1):
        gain, likelihood = gains(model, samples)
        if bonus is not None:
            gain = gain + bonus
        taken, total, gap = assign(gain, samples.start, samples.end, overlap_tolerance, candidates)
        score = float(sum(likelihood[p, k] for p, k in taken))
        converged = previous is not None and set(taken) == set(previous)
        if best is None or score > best.likelihood_ratio:
            best = Solution(tuple(taken), model, iteration, converged, total, gap, score)
        if converged:
            return replace(best, converged=True)
        previous = taken
        model = refit(taken, samples, model)
    return best


def identify_hindsight(tracks: TrackArrays, people: Mapping[str, tuple[np.ndarray, np.ndarray]],
                       prior: PaperModel = PRIOR, max_iterations: int = MAX_ITERATIONS,
                       held: Mapping[str, np.ndarray] | None = None,
                       held_weight_g: float = HELD_WEIGHT_G) -> HindsightResult:
    """Assign every fragment of `tracks` at once, the regression learnt on the way.

    people: name -> (time_ns, vertical acceleration in g), as for the paper's `identify`
    (`vertical_acceleration` of each wearer's waist on the venue clock). held (optional): name -> the
    track id the live engine gave that person at each of `tracks.frame_ns` (0: none); each second of it
    on a fragment adds `held_weight_g` x 1 s to that pair's gain (the engine's other cues, the head's
    bob, a stature learnt over minutes, speak there)."""
    fragments = split_fragments(tracks, prior.window_s)
    frames = np.asarray(tracks.frame_ns, dtype=np.int64)
    names = tuple(sorted(people))
    verticals = np.array([on_frame_grid(frames, n, *people[n]) for n in names]).reshape(len(names), len(frames))
    label = np.repeat(np.arange(len(fragments.track_id)), np.diff(fragments.offsets))
    frame_s = frame_period_s(frames) if len(frames) > 1 else 0.05
    samples = Samples(label, fragments.speed_mps, verticals[:, fragments.frame_index], fragments.start_frame,
                      fragments.end_frame, frame_s)
    bonus = None
    if held is not None:
        bonus = np.zeros((len(names), len(fragments.track_id)))
        track_of_entry = fragments.track_id[label]
        for p, name in enumerate(names):
            ids = held.get(name)
            if ids is not None:
                on = np.asarray(ids)[fragments.frame_index] == track_of_entry
                bonus[p] = held_weight_g * frame_s * np.bincount(label, weights=on, minlength=len(fragments.track_id))
    return HindsightResult(names, fragments, solve(samples, prior, max_iterations, bonus=bonus))
