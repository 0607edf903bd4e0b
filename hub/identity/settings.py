"""The identity engine's settings (hub/identity/engine.py, with its rules in hub/identity/rules.py) and
its counters. What each setting does and how its value was chosen: docs/identity.md."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class IdentitySettings:
    hop_s: float = 0.2  # scored as soon as the agents' data is in, sooner than 0.5 s hops (120 s games: docs/identity.md)
    delay_s: float = 0.2  # bins are scored at least this long after the camera saw them, once every live agent's
    max_delay_s: float = 1.0  # ... data has reached them, but never later than this (a silent device holds none back)
    forget_per_s: float = 0.7  # evidence half-life about 2 s: a tracker's swap is followed within seconds
    fast_forget_per_s: float = 0.2  # ... and a fast mean (half-life 0.4 s) that overrides it where recent bins disagree
    fast_margin: float = 0.5  # ... by more than this (0: a wrong pair claimed on a camera 0.2 s off, tests)
    pedestrian_forget_per_s: float = 0.8  # ... a pedestrian's (half-life 3.1 s): its cues are weak per bin, and a
    # room's tracker breaks tracks rather than swapping them
    prior_bins: float = 4.0  # a new pair starts with this many bins at prior_cost
    prior_cost: float = 2.0
    # each side; a pair is taken when its evidence is below twice this. With the hub's honest covariance
    # 0.7 beats 0.6 (120 s games, seeds 1-3, live 93.3 / 95.7 / 96.2 % against 91.9 / 95.4 / 95.9 %)
    nobody_cost: float = 0.7
    claim_margin: float = 0.3  # a new identity must be this much better than the best assignment without it
    max_claims: int = 8  # new identities examined per hop (each costs one more assignment); the rest wait
    switch_margin: float = 0.4
    fix_every_s: float = 1.0
    fix_cost: float = 0.6  # evidence needed to send a fix
    fix_after_s: float = 2.0  # ... held for this long
    track_timeout_s: float = 0.3  # a tracker reports every frame; one that comes back gets a new id anyway
    continue_max_s: float = 5.0  # a new track can continue an agent's track that broke off this long ago (0: never)
    continue_gate_m: float = 0.7  # ... if it starts this close to where the old track's motion leads
    continue_spread_mps: float = 1.0  # ... a gate growing this fast with the gap (a chair turns, brakes)
    continue_coast_s: float = 1.0  # the old track's velocity is extrapolated at most this long
    continue_margin_m: float = 0.7  # ... and the hub expects no other agent within this much of as close
    continue_clear_m: float = 0.6  # a new track this close to another live track may be a second detection: no
    continue_height_m: float = 0.1  # ... nor one whose head height differs from the old track's by more (3 frame sd)
    birth_sd_m: float = 0.3  # a chair with no track, placed this surely by the hub, names a new track there (0: no)
    encounter_m: float = 1.3  # tracks this close may swap or merge: evidence from before they met is restarted
    encounter_keep: float = 0.2  # ... except this share of the holder's own, so its identity holds until beaten
    share_merges: bool = True  # an agent whose track ends inside a held one shares it until they part
    share_m: float = 0.6  # ... inside: this close (a merged track sits at its people's centroid)
    max_lag_s: float = 0.5  # the camera's clock offset is searched within this much of lag_prior_s (an absolute bound)
    lag_prior_s: float = 0.0  # ... the configured offset (camera stamps minus venue time)
    lag_every_s: float = 5.0
    stature_weight: float = 4.0  # per bin, x how much worse the agent's motion matched tracks of this height (0: off)
    seated_tilt_deg: float = 5.0  # ... except for an agent whose waist leans this far from walking upright (seated)
    # pedestrians, per bin: x (a right pair's correlation of head bob and waist - this pair's) (0: off)
    gait_weight: float = 4.0
    # people on foot: every window_every_s, the last window_s of every track named at once, the line from
    # activity to speed learnt anew each time in at most window_iterations rounds (hub/identity/window.py; 0: off);
    # the engine's evidence leans window_weight towards that choice (chosen on room seeds 1-5: docs/identity.md)
    window_s: float = 30.0
    window_every_s: float = 1.0
    window_iterations: int = 4
    window_weight: float = 0.5
    # ... for up to this many walkers: the hop that solves takes 10-50 ms at 10 walkers, 30-120 at 20, ~0.5 s at
    # 50 (this VM); beyond it the engine alone names tracks live (docs/identity.md)
    window_max_walkers: int = 20
    speed_sd_mps: float = 0.35
    yaw_sd_dps: float = 25.0
    course_sd_deg: float = 15.0  # a moving track's direction against a chair's dead-reckoned one (0: off)
    course_min_mps: float = 0.5  # ... compared only while both move at least this fast
    course_prior_bins: float = 10.0  # ... less the pair's usual angle, which starts at 0 with this weight in bins
    course_forget_per_s: float = 0.8  # ... and forgets at this rate (half-life 3 s)
    moving_sd: float = 0.7
    position_sd_m: float = 0.5  # beyond the camera's own error, for where an agent is expected
    walk_mps: float = 1.5  # how fast a pedestrian's expected position loses certainty when unseen
    clip: float = 9.0  # one bin's normalised squared error never counts more than this (3 sigma)
    position_clip: float = 4.0  # ... nor the hub's pose's (chairs): it can be wrong by metres, the motion cues not

    def __post_init__(self) -> None:
        checks = {"hop_s": (0.1, 10.0), "delay_s": (0.0, 10.0), "max_delay_s": (0.0, 10.0), "forget_per_s": (0.01, 1.0),
                  "fast_forget_per_s": (0.0, 1.0), "fast_margin": (0.0, 100.0),
                  "pedestrian_forget_per_s": (0.01, 1.0), "prior_bins": (0.0, 1e3),
                  "nobody_cost": (0.0, 100.0), "claim_margin": (0.0, 100.0), "switch_margin": (0.0, 100.0),
                  "fix_every_s": (0.0, 3600.0), "track_timeout_s": (0.0, 60.0), "max_lag_s": (0.0, 5.0),
                  "continue_max_s": (0.0, 60.0), "continue_gate_m": (0.0, 100.0), "continue_spread_mps": (0.0, 100.0),
                  "continue_coast_s": (0.0, 60.0), "continue_clear_m": (0.0, 100.0),
                  "continue_margin_m": (0.0, 100.0), "birth_sd_m": (0.0, 100.0), "encounter_m": (0.0, 100.0),
                  "encounter_keep": (0.0, 1.0), "share_m": (0.0, 100.0),
                  "speed_sd_mps": (1e-3, 10.0), "yaw_sd_dps": (1e-3, 1e3), "moving_sd": (1e-3, 10.0),
                  "position_sd_m": (1e-3, 100.0), "lag_prior_s": (-5.0, 5.0), "continue_height_m": (0.0, 10.0),
                  "stature_weight": (0.0, 100.0), "gait_weight": (0.0, 100.0), "seated_tilt_deg": (0.0, 90.0),
                  "course_sd_deg": (0.0, 180.0),
                  "course_min_mps": (0.0, 10.0), "course_prior_bins": (0.0, 1e4), "course_forget_per_s": (0.01, 1.0),
                  "window_s": (0.0, 600.0), "window_every_s": (0.1, 60.0), "window_iterations": (1, 20),
                  "window_weight": (0.0, 100.0), "window_max_walkers": (0, 10_000)}
        for name, (low, high) in checks.items():
            value = getattr(self, name)
            if not low <= value <= high:
                raise ValueError(f"IdentitySettings.{name} = {value}: must be within [{low}, {high}]")


@dataclass
class IdentityCounters:
    """What the engine did, for reports (`reckon eval`'s identity notes) and tests; never read back by it."""

    updates: int = 0
    pair_bins: int = 0  # cue comparisons: tracks x agents x bins, summed over updates
    max_pair_bins: int = 0  # ... in the largest update
    solves: int = 0  # assignment problems solved (one per hop, one more per examined new identity)
    max_assignment_size: int = 0  # the largest padded matrix solved (a part's tracks + agents)
    screened: int = 0  # new identities refused by the exchange bound, without a solve
    identity_changes: int = 0
    continuations: int = 0  # new tracks that inherited a broken-off track's identity at their first frame
    births: int = 0  # ... of which where the hub placed a chair that had no track (its start, a sure pose)
    encounters: int = 0  # tracks whose evidence restarted after they met others
    shares: int = 0  # agents that shared a merged track (its holder's) after their own ended inside it
    fixes: int = 0
    rows_not_numbers: int = 0  # camera rows whose x or y was NaN or inf: left out of the frame
    frames: int = 0
    tracks: int = 0
    lag_bins: int = 0
    window_solves: int = 0  # the walkers' windows named at once (hub/identity/window.py)
