"""The hub's computation without a bus: pairing, beacon passes, fixes, expected shifts, smoothing, clocks."""

import numpy as np
import pytest

from hub.chair.hub import ChairHub, HubSettings
from hub.clocks import ClockOffsets
from hub.chair.smoother import FixedLagSmoother
from protocol import messages
from protocol.session import session_from_dict

S = 1_000_000_000
Kind = messages.CorrectionKind


def venue(n_agents: int):
    return session_from_dict({
        "venue": {"name": "court", "court_length_m": 28.0, "court_width_m": 15.0,
                  "beacons": [{"id": "goal-a", "x_m": 1.2, "y_m": 7.5, "tx_power_dbm": -59.0}]},
        "agents": [{"id": f"c{i}", "wheel_diameter_m": 0.61, "start_x_m": 0.0, "start_y_m": 0.0,
                    "sensors": [{"id": f"c{i}-seat", "mount": "seat"}, {"id": f"c{i}-l", "mount": "left_wheel", "spin_axis": "+z"},
                                {"id": f"c{i}-r", "mount": "right_wheel", "spin_axis": "-z"}]} for i in range(n_agents)],
    }, where="test")


def pose(agent: str, t: int, x: float, y: float, sd: float = 0.5, sequence: int = 0, heading: float = 0.0):
    cov = np.diag([sd * sd, sd * sd, 0.01]).ravel().tolist()
    return messages.new("EstimatedPose", timestamp_ns=t, agent_id=agent, x_m=x, y_m=y, heading_rad=heading,
                        covariance=cov, method="reckon", track=messages.Track.LIVE, correction_sequence=sequence)


def impact(agent: str, t: int, peak: float = 9.0, push: tuple[float, float] = (0.0, 0.0)):
    return messages.new("ImpactEvent", timestamp_ns=t, agent_id=agent, sensor_id=f"{agent}-seat", peak_g=peak,
                        forward_g=push[0], left_g=push[1])


def send(hub, message):
    """Into the hub, arriving at its own timestamp (a link with no delay)."""
    return hub.on_message(message, message.timestamp_ns)


def corrections(outputs):
    return [o for o in outputs if messages.type_name(o) == "Correction"]


def feed_poses(hub, positions: dict, start_s: float, end_s: float, rate_hz: float = 50.0):
    out = []
    for t in np.arange(start_s, end_s, 1.0 / rate_hz):
        for agent, (x, y, *heading) in positions.items():
            out += send(hub, pose(agent, int(t * S), x, y, heading=heading[0] if heading else 0.0))
    return out


def test_three_impacts_at_once_pair_the_two_in_contact_by_gating():
    hub = ChairHub(venue(3), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (11.2, 5.0), "c2": (20.0, 5.0)}  # c0-c1 1.2 m apart, c2 far
    feed_poses(hub, positions, 0.0, 2.0)
    for agent in positions:
        send(hub, impact(agent, int(2.0 * S) + 1000))
    out = corrections(feed_poses(hub, positions, 2.0, 4.0))
    assert sorted(c.agent_id for c in out) == ["c0", "c1"]
    assert hub.counters.pairs == 1 and hub.counters.groups == 1
    by_agent = {c.agent_id: c for c in out}
    # pulled together along the line: c0 (left) moves right, c1 moves left, by the 0.3 m excess shared
    assert by_agent["c0"].dx_m > 0 > by_agent["c1"].dx_m
    assert by_agent["c0"].other_agent_id == "c1" and by_agent["c0"].kind == Kind.COLLISION


@pytest.mark.parametrize("heading_c1, push_c1, paired", [
    (0.0, (8.0, 1.0), True), (0.0, (-8.0, 0.5), False), (0.0, (0.5, 8.0), False), (np.pi, (-8.0, 0.0), True),
    (np.pi, (8.0, 0.0), False)], ids=["opposite", "same-way", "across", "facing-back", "facing-back-same-way"])
def test_two_impacts_are_a_contact_only_if_their_pushes_point_opposite_ways(heading_c1, push_c1, paired):
    # c0 (heading 0) is pushed back (-x in the court); a contact pushes c1 +x in the court, which is its
    # own forward when it heads 0 and its backward when it heads pi
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (11.0, 5.0, heading_c1)}
    feed_poses(hub, positions, 0.0, 2.0)
    send(hub, impact("c0", int(2.0 * S), push=(-8.0, -0.5)))
    send(hub, impact("c1", int(2.0 * S) + 1000, push=push_c1))
    out = corrections(feed_poses(hub, positions, 2.0, 4.0))
    assert (hub.counters.pairs, len(out) == 2) == ((1, True) if paired else (0, False))
    assert hub.counters.pushes_not_opposed == (0 if paired else 1)


def test_the_pushes_say_which_side_the_other_chair_was_on():
    # the estimates have c1 0.9 m to c0's left; the pushes say c1 was in front of it (c0 pushed
    # back, c1 pushed forward): each chair is moved across the estimates' line, towards the pushes' line
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (10.3, 5.85)}
    feed_poses(hub, positions, 0.0, 2.0)
    send(hub, impact("c0", int(2.0 * S), push=(-8.0, 0.0)))
    send(hub, impact("c1", int(2.0 * S) + 1000, push=(8.0, 0.0)))
    by_agent = {c.agent_id: c for c in corrections(feed_poses(hub, positions, 2.0, 4.0))}
    assert by_agent["c0"].dy_m > 0.1 and by_agent["c1"].dy_m < -0.1  # towards each other's y
    assert by_agent["c0"].dx_m < 0 < by_agent["c1"].dx_m  # and apart along x, to the contact distance
    cov = np.array(by_agent["c0"].covariance).reshape(2, 2)
    assert cov[1, 1] < 1.0  # the constraint holds across the estimates' line, not only along it


@pytest.mark.parametrize("sd_x, sd_y, paired", [(0.2, 1.5, False), (1.5, 1.5, True)], ids=["sure-across", "unsure"])
def test_a_pair_is_gated_where_its_pushes_put_the_other_chair_not_only_by_distance(sd_x, sd_y, paired):
    """Poses 4.7 m apart, pushes along the line between them: the distance alone is within the gate
    either way (its variance is the poses' along the line, mostly y), but where the pushes put the
    other chair is 2 m off in x, which poses sure of their x (0.2 m) rule out: two bumps that
    coincided, not a contact (a 317 s game's chair was pulled 5 m by one such pair)."""
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (12.5, 9.0)}
    cov = np.diag([sd_x**2, sd_y**2, 0.01]).ravel().tolist()
    for t in np.arange(0.0, 4.0, 0.02):
        for agent, (x, y) in positions.items():
            hub.on_message(messages.new("EstimatedPose", timestamp_ns=int(t * S), agent_id=agent, x_m=x, y_m=y,
                                        covariance=cov, method="reckon", track=messages.Track.LIVE), int(t * S))
        if abs(t - 2.0) < 1e-9:
            away = np.array([-2.5, -4.0]) / np.hypot(2.5, 4.0)  # from c1 to c0; both head 0 (forward = +x)
            send(hub, impact("c0", int(2.0 * S), push=tuple(8.0 * away)))
            send(hub, impact("c1", int(2.0 * S) + 1000, push=tuple(-8.0 * away)))
    assert hub.counters.groups == 1 and hub.counters.pairs == (1 if paired else 0)
    assert hub.counters.gated_out == (0 if paired else 1)


def test_four_impacts_at_once_give_two_pairs():
    hub = ChairHub(venue(4), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (5.0, 5.0), "c1": (5.9, 5.0), "c2": (20.0, 9.0), "c3": (20.0, 10.0)}
    feed_poses(hub, positions, 0.0, 2.0)
    for k, agent in enumerate(positions):
        send(hub, impact(agent, int(2.0 * S) + k * 50_000_000))
    feed_poses(hub, positions, 2.0, 4.0)
    assert hub.counters.pairs == 2


def test_a_pile_up_of_two_contacts_pairs_the_impacts_that_came_together():
    """Four chairs on a 0.9 m square: c0-c2 touch, and 0.1 s later c1-c3. By distance alone every side
    of the square fits a contact (and c0-c1 comes first by name); the timing says which impacts belong
    together."""
    hub = ChairHub(venue(4), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (5.0, 5.0), "c1": (5.9, 5.0), "c2": (5.0, 5.9), "c3": (5.9, 5.9)}
    feed_poses(hub, positions, 0.0, 2.0)
    for agent, t in (("c0", 2.0), ("c2", 2.001), ("c1", 2.1), ("c3", 2.1005)):
        send(hub, impact(agent, int(t * S)))
    out = corrections(feed_poses(hub, positions, 2.0, 4.0))
    assert hub.counters.groups == 1 and hub.counters.pairs == 2
    assert sorted((c.agent_id, c.other_agent_id) for c in out) == [("c0", "c2"), ("c1", "c3"), ("c2", "c0"), ("c3", "c1")]


def test_once_contacts_have_shown_how_close_in_time_their_impacts_come_a_late_one_is_no_contact():
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (10.9, 5.0)}
    for k in range(40):  # contacts whose impacts came within 2 ms of each other
        start = 4.0 * k
        feed_poses(hub, positions, start, start + 2.0)
        send(hub, impact("c0", int((start + 2.0) * S)))
        send(hub, impact("c1", int((start + 2.0 + 0.002 * (k % 2)) * S)))
        feed_poses(hub, positions, start + 2.0, start + 4.0)
    assert hub.counters.pairs == 40 and hub.counters.not_simultaneous == 0
    sd_s = hub.pairing.timing.variance_s2() ** 0.5
    assert 0.003 <= sd_s < 0.025  # learnt down from the prior's 45 ms, still above the floor
    feed_poses(hub, positions, 160.0, 162.0)
    send(hub, impact("c0", int(162.0 * S)))
    send(hub, impact("c1", int(162.12 * S)))  # inside the pairing window, but 0.12 s apart
    assert corrections(feed_poses(hub, positions, 162.0, 164.0)) == []
    assert hub.counters.pairs == 40 and hub.counters.not_simultaneous == 1


@pytest.mark.parametrize("apart_m, weight", [(1.2, 1.0), (3.0, 2.1 / 0.59**0.5 / 1.5)])
def test_a_contact_far_from_what_the_poses_say_pulls_each_chair_less(apart_m, weight):
    """Inside the gate but 2.1 m from the contact distance (0.9 m) with 0.5 m poses: each side's
    measurement is 2.7 SDs from its chair's pose, so its covariance grows by 2.7 / 1.5 (Huber), and a
    chair whose partner is metres off while stating less is not dragged the whole way."""
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (10.0, 5.0), "c1": (10.0 + apart_m, 5.0)}
    feed_poses(hub, positions, 0.0, 2.0)
    send(hub, impact("c0", int(2.0 * S)))
    send(hub, impact("c1", int(2.0 * S)))
    out = corrections(feed_poses(hub, positions, 2.0, 4.0))
    assert hub.counters.pairs == 1 and len(out) == 2
    for correction in out:
        assert abs(correction.dx_m) == pytest.approx(apart_m - 0.9)  # the measurement is the contact's, whole
        assert correction.covariance[0] == pytest.approx((0.25 + 0.09) * weight)  # the other's pose + the contact's


def test_a_lone_impact_and_a_far_pair_change_nothing():
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"collision"})))
    positions = {"c0": (2.0, 2.0), "c1": (25.0, 12.0)}  # 24 m apart with 0.5 m uncertainty: no contact
    feed_poses(hub, positions, 0.0, 2.0)
    send(hub, impact("c0", int(2.0 * S)))
    send(hub, impact("c1", int(2.1 * S)))
    assert corrections(feed_poses(hub, positions, 2.0, 4.0)) == []
    assert hub.counters.gated_out == 1 and hub.counters.pairs == 0


def test_live_pose_carries_the_expected_shift_until_the_edge_acknowledges_it():
    hub = ChairHub(venue(1), HubSettings(corrections=frozenset({"camera"})))
    feed_poses(hub, {"c0": (10.0, 5.0)}, 0.0, 1.0)
    fix = messages.new("PositionFix", timestamp_ns=int(0.9 * S), agent_id="c0", kind=Kind.VIDEO, x_m=11.0, y_m=5.0,
                       covariance=[0.25, 0.0, 0.0, 0.25], source_id="camera-1")
    (correction,) = corrections(send(hub, fix))
    assert correction.sequence == 1 and correction.dx_m == pytest.approx(1.0)
    # edge pose that does not yet hold the correction: the hub adds the shift it expects (gain 0.5)
    live = send(hub, pose("c0", int(1.0 * S), 10.0, 5.0, sequence=0))[0]
    assert live.x_m == pytest.approx(10.5)
    assert live.correction_sequence == 1
    # the edge applied it: its own pose now holds the shift; the hub must not add it twice
    live = send(hub, pose("c0", int(1.02 * S), 10.5, 5.0, sequence=1))[0]
    assert live.x_m == pytest.approx(10.5)


def test_a_fix_with_a_bad_covariance_is_refused_with_the_value():
    hub = ChairHub(venue(1))
    feed_poses(hub, {"c0": (10.0, 5.0)}, 0.0, 0.5)
    fix = messages.new("PositionFix", timestamp_ns=1, agent_id="c0", kind=Kind.MANUAL, x_m=1.0, y_m=1.0,
                       covariance=[1.0, 0.0, 0.0, -1.0])
    with pytest.raises(ValueError, match="positive-definite"):
        send(hub, fix)


def test_a_beacon_pass_gives_one_fix_when_it_ends():
    hub = ChairHub(venue(1), HubSettings(corrections=frozenset({"beacon"})))
    feed_poses(hub, {"c0": (3.0, 7.5)}, 0.0, 1.0)
    for k, rssi in enumerate([-70.0, -62.0, -58.0, -63.0, -71.0]):
        sighting = messages.new("BeaconSighting", timestamp_ns=int((1.0 + 0.2 * k) * S), agent_id="c0",
                                sensor_id="c0-seat", beacon_id="goal-a", rssi_dbm=rssi)
        assert send(hub, sighting) == []
    assert corrections(feed_poses(hub, {"c0": (3.0, 7.5)}, 1.0, 3.0)) == []  # 1.5 s after the last: not yet
    (fix,) = corrections(feed_poses(hub, {"c0": (3.0, 7.5)}, 3.0, 4.0))
    assert fix.kind == Kind.BEACON and fix.source_id == "goal-a"
    assert fix.dx_m == pytest.approx(1.2 - 3.0)  # towards the beacon, measured at the strongest sighting


def test_refined_track_takes_a_share_of_a_later_correction():
    hub = ChairHub(venue(1), HubSettings(lag_s=2.0, corrections=frozenset({"fix"})))
    refined = []
    for k in range(200):  # the edge's uncertainty grows as it drives
        sd = 0.1 + 0.02 * k
        out = send(hub, pose("c0", int(k * 0.02 * S), 0.1 * k, 0.0, sd=sd))
        refined += [o for o in out if o.track == messages.Track.REFINED]
    fix = messages.new("PositionFix", timestamp_ns=int(3.98 * S), agent_id="c0", kind=Kind.MANUAL, x_m=19.9 + 1.0,
                       y_m=0.0, covariance=[0.01, 0.0, 0.0, 0.01])
    send(hub, fix)
    refined += [o for o in hub.flush() if o.track == messages.Track.REFINED]
    shift = {o.timestamp_ns: o.x_m - 0.1 * round(o.timestamp_ns / (0.02 * S)) for o in refined}
    times = sorted(shift)
    before_window = [shift[t] for t in times if t < 1.9 * S]
    in_window = [shift[t] for t in times if t >= 2.0 * S]
    assert max(abs(s) for s in before_window) < 1e-9  # already published before the fix: untouched
    assert all(b >= a - 1e-12 for a, b in zip(in_window, in_window[1:]))  # grows towards the fix
    assert 0.0 < in_window[0] < in_window[-1] <= 1.0


def test_smoother_memory_is_bounded():
    smoother = FixedLagSmoother(lag_s=1.0, max_entries=52)
    cov = np.eye(3).ravel().tolist()
    arrays = smoother.time_ns.nbytes + smoother.rows.nbytes
    for k in range(10_000):
        smoother.add(k * 20_000_000, 0.0, 0.0, 0.0, cov)
        assert len(smoother) <= 52
    assert smoother.time_ns.nbytes + smoother.rows.nbytes == arrays


def test_clock_offset_is_the_lower_envelope_of_arrival_minus_sample_time():
    clocks = ClockOffsets(window_s=10.0)
    rng = np.random.default_rng(1)
    offset = 5 * S
    for k in range(2000):
        sample = k * 10_000_000
        clocks.observe("s", sample, sample + offset + int((0.02 + rng.exponential(0.01)) * S))
    assert abs(clocks.offset_ns("s") - (offset + 0.02 * S)) < 0.002 * S
    assert clocks.offset_ns("unknown") == 0


def test_clock_offsets_keep_at_most_max_devices_the_first_seen_forgotten_first():
    clocks = ClockOffsets(max_devices=4)
    for k in range(10):  # a stream of made-up sensor ids
        clocks.observe(f"fake-{k}", 0, (k + 1) * S)
    assert len(clocks.envelopes) == 4 and clocks.forgotten == 6
    assert clocks.offset_ns("fake-9") == 10 * S and clocks.offset_ns("fake-0") == 0  # the oldest went
    with pytest.raises(ValueError, match="max_devices 0"):
        ClockOffsets(max_devices=0)


def video_fix(agent: str, t: int, x: float, y: float, sd: float = 0.085, source: str = "cam1:7"):
    return messages.new("PositionFix", timestamp_ns=t, agent_id=agent, kind=Kind.VIDEO, x_m=x, y_m=y,
                        covariance=[sd * sd, 0.0, 0.0, sd * sd], source_id=source)


def test_the_covariance_the_edge_is_missing_grows_with_travel_and_time_and_shrinks_with_a_fix():
    settings = HubSettings(corrections=frozenset({"camera"}), extra_m2_per_m=0.003, extra_m2_per_s=0.0005)
    hub = ChairHub(venue(1), settings)
    for k in range(101):  # 2 s, 5 m along x: 0.003 x 5 + 0.0005 x 2 = 0.016 m^2 per axis
        send(hub, pose("c0", int(k * 0.02 * S), 2.5 * k * 0.02, 0.0, sd=0.05))
    extra = hub.agents["c0"].extra
    assert extra[0, 0] == pytest.approx(0.016, rel=1e-3) and extra[0, 1] == 0.0
    published = send(hub, pose("c0", int(2.02 * S), 5.05, 0.0, sd=0.05))[0]
    assert np.sqrt(published.covariance[0]) == pytest.approx(np.hypot(0.05, np.sqrt(extra[0, 0])), rel=1e-2)
    send(hub, video_fix("c0", int(2.0 * S), 5.0, 0.0))
    send(hub, pose("c0", int(2.04 * S), 5.1, 0.0, sd=0.05))
    assert 0.0 < hub.agents["c0"].extra[0, 0] < 0.016  # the honest posterior holds less beyond the edge's


def test_a_pose_off_by_a_metre_with_a_small_sd_is_repaired_by_a_consistent_video_track():
    """The edge says 5 cm but sits 1 m off (a wrong fix taken, a shove): the gate refuses the right
    track's fixes, until `relock_after` of them in a row agree on the offset."""
    settings = HubSettings(corrections=frozenset({"camera"}), extra_m2_per_m=0.0, extra_m2_per_s=0.0)
    hub = ChairHub(venue(1), settings)
    taken = []
    for k in range(300):  # 6 s standing, the edge at x = 10, the camera's track at x = 11
        t = int(k * 0.02 * S)
        sequence = hub.agents["c0"].sequence  # an edge that takes every correction at once
        send(hub, pose("c0", t, 10.0, 5.0, sd=0.05, sequence=sequence))
        if k % 50 == 10:
            taken += corrections(send(hub, video_fix("c0", t, 11.0 + 0.02 * (k % 3), 5.0)))
    assert hub.counters.gated_out == settings.relock_after - 1
    assert hub.counters.relocks == 1 and len(taken) >= 2
    assert taken[0].dx_m == pytest.approx(1.0, abs=0.05)
    assert hub.agents["c0"].extra[0, 0] > 0.0  # the offset became uncertainty: later fixes pass the gate


def test_fixes_from_different_tracks_or_with_scattered_offsets_do_not_relock():
    settings = HubSettings(corrections=frozenset({"camera"}), extra_m2_per_m=0.0, extra_m2_per_s=0.0)
    for sources, offsets in ((("cam1:1", "cam1:2", "cam1:1", "cam1:2"), (1.0, 1.0, 1.0, 1.0)),
                             (("cam1:1",) * 4, (1.0, -1.0, 1.0, -1.0))):
        hub = ChairHub(venue(1), settings)
        for k in range(200):
            t = int(k * 0.02 * S)
            send(hub, pose("c0", t, 10.0, 5.0, sd=0.05))
            if k % 50 == 10:
                send(hub, video_fix("c0", t, 10.0 + offsets[k // 50], 5.0, source=sources[k // 50]))
        assert hub.counters.relocks == 0 and hub.counters.gated_out == 4


def test_a_fix_inside_a_gap_in_the_poses_is_compared_with_where_the_chair_was_then():
    """The edge's poses stop for 2 s (its link stalled) while the chair rolls on at 1 m/s; a camera fix from
    inside the gap must be compared with the poses around it, interpolated, not with the last pose before
    it (1 m behind, with a 5 cm sd: that fix was refused as an outlier)."""
    settings = HubSettings(corrections=frozenset({"camera"}), extra_m2_per_m=0.0, extra_m2_per_s=0.0, relock_after=0)
    hub = ChairHub(venue(1), settings)
    out = []
    for k in range(301):  # 0-6 s along x at 1 m/s, no poses from 2 to 4 s
        t_s = k * 0.02
        if not 2.0 < t_s < 4.0:
            out += send(hub, pose("c0", int(t_s * S), t_s, 5.0, sd=0.05))
        if k == 100:
            out += send(hub, video_fix("c0", int(3.0 * S), 3.02, 5.0))  # where the chair was at 3 s
    taken = corrections(out)
    assert hub.counters.gated_out == 0 and len(taken) == 1
    assert taken[0].dx_m == pytest.approx(0.02, abs=0.02) and taken[0].dy_m == pytest.approx(0.0, abs=0.02)


def test_corrections_an_edge_never_takes_are_held_in_bounded_memory_and_still_add_up():
    """An edge deaf to the hub (a replay, a lost link) acknowledges nothing: the hub keeps adding what
    it sent, in at most PENDING_MAX entries, and drops it all once a pose says the edge took it."""
    from hub.chair.hub import PENDING_MAX

    hub = ChairHub(venue(1), HubSettings(corrections=frozenset({"fix"})))
    sent = []
    for k in range(60):
        t = int((k + 1) * 0.5 * S)
        send(hub, pose("c0", t, 0.0, 0.0, sd=1.0))
        fix = messages.new("PositionFix", timestamp_ns=t, agent_id="c0", kind=Kind.MANUAL, x_m=0.5, y_m=0.0,
                           covariance=[0.01, 0.0, 0.0, 0.01], source_id="operator")
        sent += corrections(send(hub, fix))
        assert len(hub.agents["c0"].pending) <= PENDING_MAX
    assert len(sent) == 60 and hub.counters.pending_folded == 60 - PENDING_MAX
    live = send(hub, pose("c0", int(31 * S), 0.0, 0.0, sd=1.0))[0]
    # the first fix moved the chair 0.495 m (gain 1 / 1.01), the rest the little left: none lost
    assert live.x_m == pytest.approx(0.5, abs=0.005)
    taken = send(hub, pose("c0", int(31.02 * S), 0.0, 0.0, sd=1.0, sequence=sent[-1].sequence))[0]
    assert hub.agents["c0"].pending == [] and taken.x_m == 0.0  # the edge holds them all now


def test_a_pose_that_is_not_numbers_is_refused_by_name_and_changes_nothing():
    hub = ChairHub(venue(1))
    send(hub, pose("c0", S, 1.0, 2.0))
    bad = pose("c0", S + S // 50, float("nan"), 2.0)
    with pytest.raises(ValueError, match=r"EstimatedPose of c0 at .*x_m nan.*must be finite"):
        send(hub, bad)
    bad = pose("c0", S + S // 50, 1.0, 2.0)
    bad.covariance[4] = float("inf")
    with pytest.raises(ValueError, match="covariance .*inf"):
        send(hub, bad)
    assert hub.agents["c0"].poses == 1 and len(hub.agents["c0"].smoother) == 1


def test_a_clock_jump_ahead_does_not_stop_the_refined_track():
    """One pose far in the future (a device clock glitch), then the stream goes on: the hub starts the
    agent's timeline again instead of refusing every later pose as older than that one."""
    hub = ChairHub(venue(1), HubSettings(lag_s=1.0))
    refined = []
    def feed(start_s, count):
        for k in range(count):
            for out in send(hub, pose("c0", int((start_s + k / 50) * S), 1.0, 2.0)):
                if out.track == messages.Track.REFINED:
                    refined.append(out.timestamp_ns)
    feed(1.0, 100)
    send(hub, pose("c0", 10**6 * S, 1.0, 2.0))  # a jump of eleven days
    before = len(refined)
    feed(3.0, 200)
    assert hub.counters.clock_restarts == 1
    assert len(refined) > before + 100  # the poses after the jump leave as refined, 1 s late, as before it
    assert hub.agents["c0"].latest_ns == int((3.0 + 199 / 50) * S)


@pytest.mark.parametrize("make, named", [
    (lambda: impact("c0", 2 * S, peak=float("nan")), "ImpactEvent of c0 .*peak_g nan"),
    (lambda: impact("c0", 2 * S, push=(float("inf"), 0.0)), "ImpactEvent of c0 .*forward_g inf"),
    (lambda: messages.new("BeaconSighting", timestamp_ns=2 * S, agent_id="c0", sensor_id="c0-seat", beacon_id="goal-a",
                          rssi_dbm=float("nan")), "BeaconSighting of c0 .*rssi_dbm nan"),
    (lambda: messages.new("PositionFix", timestamp_ns=2 * S, agent_id="c0", kind=Kind.MANUAL, x_m=float("nan"), y_m=1.0,
                          covariance=[0.01, 0.0, 0.0, 0.01], source_id="operator"), "PositionFix for c0 .*x_m nan"),
])
def test_inputs_that_are_not_numbers_are_refused_by_name_and_leave_nothing_behind(make, named):
    hub = ChairHub(venue(2), HubSettings(corrections=frozenset({"beacon", "collision", "fix"})))
    with pytest.raises(ValueError, match=named):
        send(hub, make())
    assert not hub.pairing.impacts and not hub.agents["c0"].passes and not hub.agents["c0"].fixes
    assert not hub.beacon_levels.levels["goal-a"].peaks


def test_with_a_camera_on_a_pose_that_is_not_numbers_is_refused_before_the_identity_engine_takes_it():
    from hub.venue import VenueHub

    hub = VenueHub(venue(1), HubSettings(corrections=frozenset({"camera"})))
    hub.on_message(messages.new("CameraFrame", timestamp_ns=S, camera_id="cam1", frame=1), S)
    assert hub.identity is not None
    seen = []
    take = hub.identity.on_message
    hub.identity.on_message = lambda message: seen.append(message) or take(message)
    hub.on_message(pose("c0", S, 1.0, 2.0), S)
    with pytest.raises(ValueError, match="EstimatedPose of c0 .*heading_rad nan"):
        hub.on_message(pose("c0", S + S // 50, 1.0, 2.0, heading=float("nan")), S + S // 50)
    assert len(seen) == 1  # the good pose only
