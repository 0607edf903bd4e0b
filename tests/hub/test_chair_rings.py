"""The chair hub's two rings of arrays (the smoother's and the pose history) against the plain
recursion and look-up they replace, bit for bit, across their wrap-arounds."""

from collections import deque

import numpy as np
import pytest

from hub.chair.history import PoseHistory
from hub.chair.smoother import FixedLagSmoother

MS = 1_000_000


class LoopSmoother:
    """The smoother's recursion as a loop over one record per pose (docs: hub/chair/smoother.py)."""

    def __init__(self, lag_s: float, max_entries: int):
        self.lag_ns, self.entries = int(lag_s * 1e9), deque(maxlen=max_entries)

    def add(self, time_ns, x, y, heading, covariance):
        if self.entries and time_ns <= self.entries[-1]["t"]:
            return []
        out = []
        if len(self.entries) == self.entries.maxlen:
            out.append(self._emit(self.entries.popleft()))
        variance = 0.5 * float(covariance[0, 0] + covariance[1, 1])
        self.entries.append({"t": time_ns, "xy": np.array([x, y]), "h": heading, "c": covariance.ravel().tolist(),
                             "q": variance, "p": variance, "d": np.zeros(2)})
        while self.entries and time_ns - self.entries[0]["t"] >= self.lag_ns:
            out.append(self._emit(self.entries.popleft()))
        return out

    def correct(self, measured_ns, shift, variance_after):
        if not self.entries:
            return
        self.entries[-1]["p"] = min(variance_after, self.entries[-1]["p"])
        running = np.array(shift, dtype=float)
        k = len(self.entries) - 1
        while k > 0 and self.entries[k]["t"] > measured_ns:
            self.entries[k]["d"] += running
            k -= 1
        self.entries[k]["d"] += running
        for j in range(k - 1, -1, -1):
            before = self.entries[j + 1]["q"]
            running = min(self.entries[j]["p"] / before, 1.0) * running if before > 0 else 0.0 * running
            self.entries[j]["d"] += running

    @staticmethod
    def _emit(entry):
        xy = entry["xy"] + entry["d"]
        return entry["t"], float(xy[0]), float(xy[1]), entry["h"], entry["c"]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_smoother_gives_the_loops_refined_poses_exactly(seed):
    rng = np.random.default_rng(seed)
    ring, loop = FixedLagSmoother(1.0, 52), LoopSmoother(1.0, 52)
    unbuilt = FixedLagSmoother(1.0, 52)  # every other pose's leavers not built (nobody took the refined track)
    t, out_ring, out_loop, out_unbuilt = 0, [], [], []
    for k in range(3000):
        t += int(rng.choice([20, 20, 20, 7, 300, -40])) * MS  # steady, quick, a gap, out of order
        sd = rng.uniform(0.05, 2.0)
        cov = np.diag([sd * sd, sd * sd * rng.uniform(0.5, 2), 0.01])
        x, y, heading = rng.normal(0, 10, 3)
        out_ring += ring.add(t, x, y, heading, cov.ravel().tolist())
        out_loop += loop.add(t, x, y, heading, cov)
        out_unbuilt += unbuilt.add(t, x, y, heading, cov.ravel().tolist(), build=k % 2 == 0)
        if rng.random() < 0.05:  # a correction measured now, a little earlier, or before every held pose
            measured = t - int(rng.choice([0, 200, 900, 5000])) * MS
            shift, after = rng.normal(0, 1, 2), rng.uniform(0.0, 1.0) * sd * sd
            ring.correct(measured, shift, after)
            loop.correct(measured, shift, after)
            unbuilt.correct(measured, shift, after)
    out_ring += ring.flush()
    out_loop += [loop._emit(entry) for entry in loop.entries]
    assert len(out_ring) == len(out_loop) > 1500
    assert out_ring == out_loop  # every float equal, not close
    assert len(out_unbuilt) == len(out_ring) - len(unbuilt) and 0 < out_unbuilt.count(None) < len(out_unbuilt)
    assert all(mine is None or mine == theirs for mine, theirs in zip(out_unbuilt, out_ring))


def test_a_correction_with_no_variance_before_stops_at_that_pose():
    smoother = FixedLagSmoother(10.0, 600)
    for k in range(5):
        smoother.add(k * 20 * MS, 0.0, 0.0, 0.0, [0.0] * 9 if k == 2 else np.eye(3).ravel().tolist())
    smoother.correct(4 * 20 * MS, np.array([1.0, -1.0]), 0.5)
    offsets = [(x, y) for _, x, y, _, _ in smoother.flush()]
    assert offsets[4] == (1.0, -1.0)  # the measured pose takes the whole shift
    assert offsets[3] == (1.0, -1.0)  # min(p3 / q4, 1) = 1
    assert offsets[:3] == [(0.0, 0.0), (0.0, 0.0), (0.0, -0.0)]  # q of pose 2 is 0: nothing before it moves


def test_the_history_looks_up_as_a_scan_of_the_last_poses_does():
    rng = np.random.default_rng(4)
    history, reference = PoseHistory(64), deque(maxlen=64)
    t = 0
    for k in range(1000):
        t += int(rng.choice([20, 20, -30, 500])) * MS  # a clock offset that moved makes poses go back in time
        cov = np.array([[rng.uniform(0.1, 1), 0.1, 0], [0.1, rng.uniform(0.1, 1), 0], [0, 0, 0.01]])
        x, y, heading = rng.normal(0, 10, 3)
        history.append(t, x, y, cov.ravel().tolist(), heading)
        reference.append((t, x, y, cov[:2, :2].copy(), heading))
        assert len(history) == len(reference)
        for asked in (t, t - 10 * MS, t - int(rng.uniform(0, 2000)) * MS, t - 10**12):
            found = next((i for i in range(len(reference) - 1, -1, -1) if reference[i][0] <= asked), None)
            assert history.last_at(asked) == found
            if found is not None:
                xy, covariance = history.position(found)
                assert history.time_at(found) == reference[found][0]
                assert (xy.tolist(), history.heading(found)) == ([reference[found][1], reference[found][2]],
                                                                 reference[found][4])
                assert np.array_equal(covariance, reference[found][3])


def test_the_rings_do_not_grow():
    smoother, history = FixedLagSmoother(0.5, 27), PoseHistory(16)
    sizes = (smoother.rows.nbytes, smoother.time_ns.nbytes, history.rows.nbytes, history.time_ns.nbytes)
    for k in range(5000):
        smoother.add(k * 20 * MS, 1.0, 2.0, 0.0, np.eye(3).ravel().tolist())
        history.append(k * 20 * MS, 1.0, 2.0, np.eye(3).ravel().tolist(), 0.0)
    assert len(smoother) <= 27 and len(history) == 16
    assert (smoother.rows.nbytes, smoother.time_ns.nbytes, history.rows.nbytes, history.time_ns.nbytes) == sizes
    history.clear()
    assert len(history) == 0 and history.last_at(10**15) is None
