"""Stone Soup's GNN tracker, configured from a fusion TrackerConfig (one 2-D constant-velocity
sensor set-up), as the baseline of bench/tracker_scan.py and bench/gospa.py.

The parts, and what of fusion's configuration each takes:
- transition: CombinedLinearGaussianTransitionModel of two ConstantVelocity(q), q =
  motion.accel_psd_m2s3 (Stone Soup's noise_diff_coeff is the same density: Q_axis =
  q [[dt^3/3, dt^2/2], [dt^2/2, dt]]);
- measurement: LinearGaussian on (x, y) with R = diag(std_m^2) for a Cartesian sensor, or
  CartesianToBearingRange at the radar's position with R = diag(bearing^2, range^2) (Stone
  Soup orders a radar measurement [bearing, range]) and the extended Kalman updater;
- association: GNNWith2DAssignment over a DistanceHypothesiser with the Mahalanobis measure and
  missed_distance = sqrt(chi2_2(gate.probability)), the same gate as fusion's NIS <= chi2_2(p);
- initiation: MultiMeasurementInitiator (single-point prior: position from the measurement,
  velocity variance init.velocity_std_mps^2), confirming at lifecycle.confirm_m updates (the
  first measurement is one), its holding tracks deleted by MofNDeleter (confirm_n scans
  without confirm_m updates), the same M-of-N as fusion's for one sensor that sees every track;
- deletion: UpdateTimeStepsDeleter(max_misses + 1), fusion's "more than max_misses scans in a
  row without a hit" for one sensor.
The tracker associates its confirmed tracks first and gives the initiator the leftovers.
"""

from __future__ import annotations

import datetime
from collections.abc import Iterator

import numpy as np
from scipy.stats import chi2

from fusion.config import CartesianSensorConfig, RadarSensorConfig, TrackerConfig

T0 = datetime.datetime(2026, 1, 1)


def _mofn_deleter(m: int, n: int):  # a Stone Soup Property class, built once Stone Soup is imported
    from stonesoup.deleter.base import Deleter
    from stonesoup.types.update import Update

    class MofNDeleter(Deleter):
        """Deletes a holding track that has had n scans (states) and fewer than m updates."""

        def check_for_deletion(self, track, **kwargs) -> bool:
            return len(track) >= n and sum(isinstance(s, Update) for s in track) < m

    return MofNDeleter()


class StoneSoupGNN:
    """Stone Soup's MultiTargetTracker over scans given as (t_ns, measurements (k, 2)) in
    fusion's layout ([x, y] or [range_m, bearing_rad]); `step` runs one scan."""

    def __init__(self, cfg: TrackerConfig) -> None:
        from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
        from stonesoup.deleter.time import UpdateTimeStepsDeleter
        from stonesoup.hypothesiser.distance import DistanceHypothesiser
        from stonesoup.initiator.simple import MultiMeasurementInitiator
        from stonesoup.measures import Mahalanobis
        from stonesoup.models.measurement.linear import LinearGaussian
        from stonesoup.models.measurement.nonlinear import CartesianToBearingRange
        from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
        from stonesoup.predictor.kalman import KalmanPredictor
        from stonesoup.tracker.simple import MultiTargetTracker
        from stonesoup.types.state import GaussianState
        from stonesoup.updater.kalman import ExtendedKalmanUpdater, KalmanUpdater

        if cfg.motion.model != "cv" or cfg.motion.ndim != 2 or len(cfg.sensors) != 1:
            raise ValueError("the Stone Soup baseline takes a 2-D constant-velocity model and one sensor")
        (sensor,) = cfg.sensors
        q = cfg.motion.accel_psd_m2s3
        tm = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
        self.radar = isinstance(sensor, RadarSensorConfig)
        if isinstance(sensor, CartesianSensorConfig):
            assert sensor.std_m is not None
            mm = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.diag(np.square(sensor.std_m)))
            updater = KalmanUpdater(mm)
        else:
            assert sensor.range_std_m is not None and sensor.bearing_std_rad is not None
            pos = np.asarray(sensor.position_m or [0.0, 0.0], dtype=np.float64)
            mm = CartesianToBearingRange(ndim_state=4, mapping=(0, 2),
                                         noise_covar=np.diag([sensor.bearing_std_rad**2, sensor.range_std_m**2]),
                                         translation_offset=pos.reshape(2, 1))
            updater = ExtendedKalmanUpdater(mm)
        self.mm = mm
        gate = float(np.sqrt(chi2.ppf(cfg.gate.probability, 2)))
        hyp = DistanceHypothesiser(KalmanPredictor(tm), updater, measure=Mahalanobis(), missed_distance=gate)
        assoc = GNNWith2DAssignment(hyp)
        lc = cfg.lifecycle
        v2 = cfg.init.velocity_std_mps**2
        init = MultiMeasurementInitiator(
            prior_state=GaussianState(np.zeros((4, 1)), np.diag([0.0, v2, 0.0, v2])),
            measurement_model=mm, deleter=_mofn_deleter(lc.confirm_m, lc.confirm_n), data_associator=assoc,
            updater=updater, min_points=lc.confirm_m)
        self._feed: list = []
        self.tracker = MultiTargetTracker(initiator=init, deleter=UpdateTimeStepsDeleter(lc.max_misses + 1),
                                          detector=_Feed(self._feed), data_associator=assoc, updater=updater)
        self._it = iter(self.tracker)

    def detections(self, t_ns: int, Z: np.ndarray) -> tuple[datetime.datetime, set]:
        """One scan in Stone Soup's types (built outside the timed step)."""
        from stonesoup.types.angle import Bearing
        from stonesoup.types.array import StateVector
        from stonesoup.types.detection import Detection

        ts = T0 + datetime.timedelta(microseconds=t_ns / 1000)
        if self.radar:
            vecs = [StateVector([Bearing(z[1]), z[0]]) for z in Z]
        else:
            vecs = [StateVector([z[0], z[1]]) for z in Z]
        return ts, {Detection(v, timestamp=ts, measurement_model=self.mm) for v in vecs}

    def step(self, scan: tuple[datetime.datetime, set]) -> None:
        self._feed.append(scan)
        next(self._it)

    def positions(self) -> np.ndarray:
        """(n, 2) positions of the confirmed tracks at the last scan."""
        return np.array([[float(t.state_vector[0, 0]), float(t.state_vector[2, 0])] for t in self.tracker.tracks],
                        dtype=np.float64).reshape(-1, 2)


class _Feed:
    """The tracker's detector: yields the scans appended to `queue`, one per step."""

    def __init__(self, queue: list) -> None:
        self.queue = queue

    def __iter__(self) -> Iterator:
        while self.queue:
            yield self.queue.pop(0)
