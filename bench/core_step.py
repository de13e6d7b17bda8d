"""Cost of one predict + update, fusion against filterpy and a textbook numpy loop, same process.

KF: 4-state 2-D constant velocity (dt 0.1 s, q 0.01), 2-D position measured (R = 0.01 I).
EKF: radar2d of shared/scenarios.md (range 10 m, bearing 0.01 rad). Every implementation runs
the same measurements; the agreement of their estimates is checked before timing (filterpy and
the textbook loop use (I - K H) P, so they agree with fusion's Joseph form to rounding).
fusion runs through its public API, inputs validated unless check=False: "fusion KF" / "fusion
EKF" time KalmanFilter / ExtendedKalmanFilter .predict then .update (two calls, as the tracker's
per-pair path and a single-track user do); "step()" rows time the fused .step(state, t_ns, z,
model) (one call, the same Update bit for bit). The floor rows are the compiled calls without
the methods around them: "two calls alone" the two of the two-call path
(fusion.core.single.predict and update, the C extension where it was built), "step call alone"
the one of step() (fusion.core.single.step on the filter's plan for the model,
fusion.core.step_plan); the "numba" rows the same calls through their numba twins (what an
install without a C compiler runs).

Timing: CPU time of this process (time.process_time), so that the time spent waiting for a core
of the shared machine is not counted; the implementations are interleaved (each repeat times
each one once) and the speed-up over filterpy is taken per repeat (filterpy's time in that
repeat over the implementation's), printed as median [min, max] over the repeats, with the
goal of issue 11 (>= 10x for the validated KF and radar EKF).
Batch: fusion's stacked numpy reference (predict_arrays, update_arrays) over N tracks, per
track-step.

    python -m bench.core_step [--quick] [--no-batch]
"""

from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np

from fusion.core import single
from fusion.core.compiled_step import CHECK_Z
from fusion.core.kalman import ExtendedKalmanFilter, KalmanFilter, predict_arrays, update_arrays
from fusion.core.measurement import CartesianPosition, Radar2D, wrap_angle
from fusion.core.motion import ConstantVelocity
from fusion.core.step_plan import blob, make_plan
from fusion.core.transitions import TransitionCache
from fusion.scenarios import reference

DT = 0.1
DT_NS = 100_000_000
FLOOR = "two calls alone (floor)"
NUMBA = "two numba kernels alone"
STEP_FLOOR = "step call alone (floor)"
STEP_NUMBA = "step numba kernel alone"


def floor_setup(cv: ConstantVelocity, meas: CartesianPosition | Radar2D, Z: np.ndarray, x0: np.ndarray,
                P0: np.ndarray, *, numba: bool = False) -> tuple[Callable[[int], None], Callable[[], np.ndarray]]:
    """The two calls the public predict and update make (fusion.core.single.predict and update:
    the C extension where it was built; with numba=True their numba twins, what an install
    without a C compiler runs), with z checked as the validated filter does, but without the
    methods, dt from integer times or the fallbacks: what the two calls cost below the API."""
    FQ = TransitionCache(cv)[DT]
    predict, update = (single.predict_numba, single.update_numba) if numba else (single.predict, single.update)
    st = {"x": x0.copy(), "P": P0.copy()}
    code = meas.kernel_kind << 2 | CHECK_Z

    def step(k: int) -> None:
        p = predict(st["x"], st["P"], FQ, k, True)
        out = update(code, p.x, p.P, Z[k % len(Z)], meas.kernel_spec, meas.R, k)
        st["x"], st["P"] = out.state.x, out.state.P

    return step, lambda: st["x"]


def step_floor_setup(cv: ConstantVelocity, meas: CartesianPosition | Radar2D, Z: np.ndarray, x0: np.ndarray,
                     P0: np.ndarray, call: Callable = single.step) -> tuple[Callable[[int], None],
                                                                           Callable[[], np.ndarray]]:
    """The one call of the public step() (fusion.core.single.step: C where it was built) on a
    validating filter's plan for meas at dt, without the method around it; with
    call=single.step_numba, numba's kernel with its results allocated around it."""
    packed = blob(make_plan(TransitionCache(cv), meas, check=True), DT_NS)
    st = {"x": x0.copy(), "P": P0.copy()}

    def step(k: int) -> None:
        out = call(st["x"], st["P"], Z[k % len(Z)], packed, k)
        st["x"], st["P"] = out.state.x, out.state.P

    return step, lambda: st["x"]


CLOCK = time.process_time  # CPU seconds of this process: time spent waiting for a shared core is not counted


def _timeit(step: Callable[[int], None], n: int, repeats: int, clock: Callable[[], float] = time.perf_counter
            ) -> list[float]:
    """Seconds per call of step(k) for k in range(n), `repeats` times (after a warm-up), on `clock`."""
    for k in range(min(n, 200)):
        step(k)
    out = []
    for _ in range(repeats):
        t0 = clock()
        for k in range(n):
            step(k)
        out.append((clock() - t0) / n)
    return out


def kf_setups(n: int, seed: int = 0) -> dict[str, tuple[Callable[[int], None], Callable[[], np.ndarray]]]:
    rng = np.random.default_rng(seed)
    Z = np.cumsum(rng.normal(0, 0.1, (n, 2)), axis=0)
    cv = ConstantVelocity(ndim=2, q=0.01)
    F, Q = cv.F(DT), cv.Q_dt(DT)
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.01, 0.01])
    H, R = meas.H, meas.R
    x0, P0 = np.zeros(4), np.eye(4)
    setups = {}
    for name, check in (("fusion KF", True), ("fusion KF check=False", False)):
        kf = KalmanFilter(cv, check=check)
        box = {"s": kf.initial(x0, P0, t_ns=0)}

        def step(k: int, kf: KalmanFilter = kf, box: dict = box) -> None:
            s = box["s"]
            box["s"] = kf.update(kf.predict(s, s.t_ns + DT_NS), Z[k % n], meas).state

        setups[name] = (step, lambda box=box: box["s"].x)
        boxf = {"s": kf.initial(x0, P0, t_ns=0)}

        def fused(k: int, kf: KalmanFilter = kf, box: dict = boxf) -> None:
            s = box["s"]
            box["s"] = kf.step(s, s.t_ns + DT_NS, Z[k % n], meas).state

        setups[name.replace("KF", "KF step()")] = (fused, lambda box=boxf: box["s"].x)
    from filterpy.kalman import KalmanFilter as FilterpyKF

    f = FilterpyKF(dim_x=4, dim_z=2)
    f.x, f.P, f.F, f.Q, f.H, f.R = x0.copy()[:, None], P0.copy(), F, Q, H, R

    def fp_step(k: int) -> None:
        f.predict()
        f.update(Z[k % n][:, None])

    setups["filterpy KalmanFilter"] = (fp_step, lambda: f.x[:, 0])
    st = {"x": x0.copy(), "P": P0.copy()}
    I4 = np.eye(4)

    def np_step(k: int) -> None:
        x, P = st["x"], st["P"]
        x = F @ x
        P = F @ P @ F.T + Q
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        x = x + K @ (Z[k % n] - H @ x)
        P = (I4 - K @ H) @ P
        st["x"], st["P"] = x, P

    setups["textbook numpy"] = (np_step, lambda: st["x"])
    setups[FLOOR] = floor_setup(cv, meas, Z, x0, P0)
    setups[NUMBA] = floor_setup(cv, meas, Z, x0, P0, numba=True)
    setups[STEP_FLOOR] = step_floor_setup(cv, meas, Z, x0, P0)
    setups[STEP_NUMBA] = step_floor_setup(cv, meas, Z, x0, P0, single.step_numba)
    return setups


def ekf_setups(n: int) -> dict[str, tuple[Callable[[int], None], Callable[[], np.ndarray]]]:
    ref = reference("radar2d", seed=1)
    Z = ref.z
    cv = ConstantVelocity(ndim=2, q=0.01)
    F, Q = cv.F(DT), cv.Q_dt(DT)
    meas = Radar2D(R=[100.0, 1e-4])
    R = meas.R
    x0, P0 = ref.x0, ref.P0
    setups = {}
    for name, check in (("fusion EKF", True), ("fusion EKF check=False", False)):
        ekf = ExtendedKalmanFilter(cv, check=check)
        box = {"s": ekf.initial(x0, P0, t_ns=0)}

        def step(k: int, ekf: ExtendedKalmanFilter = ekf, box: dict = box) -> None:
            s = box["s"]
            box["s"] = ekf.update(ekf.predict(s, s.t_ns + DT_NS), Z[k % len(Z)], meas).state

        setups[name] = (step, lambda box=box: box["s"].x)
        boxf = {"s": ekf.initial(x0, P0, t_ns=0)}

        def fused(k: int, ekf: ExtendedKalmanFilter = ekf, box: dict = boxf) -> None:
            s = box["s"]
            box["s"] = ekf.step(s, s.t_ns + DT_NS, Z[k % len(Z)], meas).state

        setups[name.replace("EKF", "EKF step()")] = (fused, lambda box=boxf: box["s"].x)
    from filterpy.kalman import ExtendedKalmanFilter as FilterpyEKF

    f = FilterpyEKF(dim_x=4, dim_z=2)
    f.x, f.P, f.F, f.Q, f.R = x0.copy()[:, None], P0.copy(), F, Q, R

    def hj(x: np.ndarray) -> np.ndarray:
        return meas.jacobian(x[:, 0])

    def hx(x: np.ndarray) -> np.ndarray:
        return meas.h(x[:, 0])[:, None]

    def resid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        y = a - b
        y[1] = wrap_angle(y[1])
        return y

    def fp_step(k: int) -> None:
        f.predict()
        f.update(Z[k % len(Z)][:, None], hj, hx, residual=resid)

    setups["filterpy ExtendedKalmanFilter"] = (fp_step, lambda: f.x[:, 0])
    st = {"x": x0.copy(), "P": P0.copy()}
    I4 = np.eye(4)

    def np_step(k: int) -> None:
        x, P = st["x"], st["P"]
        x = F @ x
        P = F @ P @ F.T + Q
        dx, dy = x[0], x[2]
        r = np.hypot(dx, dy)
        H = np.array([[dx / r, 0, dy / r, 0], [-dy / r**2, 0, dx / r**2, 0]])
        S = H @ P @ H.T + R
        K = P @ H.T @ np.linalg.inv(S)
        y = Z[k % len(Z)] - np.array([r, np.arctan2(dy, dx)])
        y[1] = (y[1] + np.pi) % (2 * np.pi) - np.pi
        x = x + K @ y
        P = (I4 - K @ H) @ P
        st["x"], st["P"] = x, P

    setups["textbook numpy"] = (np_step, lambda: st["x"])
    setups[FLOOR] = floor_setup(cv, meas, Z, x0, P0)
    setups[NUMBA] = floor_setup(cv, meas, Z, x0, P0, numba=True)
    setups[STEP_FLOOR] = step_floor_setup(cv, meas, Z, x0, P0)
    setups[STEP_NUMBA] = step_floor_setup(cv, meas, Z, x0, P0, single.step_numba)
    return setups


def agreement(setups: dict, n: int) -> float:
    """Largest difference between the implementations' final estimates after n steps."""
    finals = []
    for step, final in setups.values():
        for k in range(n):
            step(k)
        finals.append(final())
    return float(max(np.max(np.abs(a - finals[0])) for a in finals))


def table(title: str, setups_fn: Callable[[int], dict], *, n: int, repeats: int) -> dict[str, dict[str, float]]:
    """Time every implementation `repeats` times, interleaved (each repeat times each once), and
    print us/step (median, min) and the speed-up over filterpy per repeat: filterpy's time in that
    repeat over the implementation's, so that both saw the same machine load. Returns, per
    implementation, us_median, us_min and the ratio's median, min and max."""
    check = agreement(setups_fn(200), 200)
    setups = setups_fn(n)
    times: dict[str, list[float]] = {name: [] for name in setups}
    for _ in range(repeats):
        for name, (step, _) in setups.items():
            times[name].extend(_timeit(step, n, 1, CLOCK))
    fp_name = next(k for k in setups if k.startswith("filterpy"))
    fp, tb = times[fp_name], times["textbook numpy"]
    print(f"{title} ({repeats} repeats x {n} steps, interleaved, CPU time; estimates agree to {check:.1e})")
    head = "vs filterpy: median [min, max]"
    print(f"  {'implementation':32s} {'us/step':>8} {'min':>7}   {head:>30} {'vs numpy':>9}")
    out = {}
    for k, v in times.items():
        r = [a / b for a, b in zip(fp, v, strict=True)]
        med = statistics.median(v)
        out[k] = {"us_median": med * 1e6, "us_min": min(v) * 1e6, "ratio_median": statistics.median(r),
                  "ratio_min": min(r), "ratio_max": max(r)}
        rn = statistics.median([a / b for a, b in zip(tb, v, strict=True)])
        print(f"  {k:32s} {med * 1e6:8.2f} {min(v) * 1e6:7.2f}   {statistics.median(r):12.2f}x "
              f"[{min(r):5.2f}, {max(r):5.2f}]     {rn:8.2f}x")
    return out


def batch(*, repeats: int) -> dict[int, float]:
    cv = ConstantVelocity(ndim=2, q=0.01)
    meas = CartesianPosition(ndim_state=4, indices=(0, 2), R=[0.01, 0.01])
    out = {}
    print("stacked kernels: predict_arrays + update_arrays over N tracks (4-state CV, 2-D position; CPU time)")
    print(f"  {'N':>6} {'us per call':>12} {'us per track-step':>18}")
    for N in (1, 10, 100, 1000):
        rng = np.random.default_rng(N)
        X = rng.normal(size=(N, 4))
        P = np.broadcast_to(np.eye(4), (N, 4, 4)).copy()
        Z = rng.normal(size=(N, 2))
        dt = np.full(N, DT)
        R = np.broadcast_to(meas.R, (N, 2, 2))

        def step(k: int, X: np.ndarray = X, P: np.ndarray = P, Z: np.ndarray = Z, dt: np.ndarray = dt,
                 R: np.ndarray = R) -> None:
            Xp, Pp = predict_arrays(X, P, cv.F(dt), cv.Q_dt(dt))
            H = meas.jacobian(Xp)
            update_arrays(Xp, Pp, Z - meas.h(Xp), H, R)

        n = max(20, 20_000 // N)
        t = statistics.median(_timeit(step, n, repeats, CLOCK))
        out[N] = t / N * 1e6
        print(f"  {N:6d} {t * 1e6:12.1f} {t / N * 1e6:18.2f}")
    return out


GOAL = 10.0  # issue 11 goal 4: the validated single-track step at least 10x filterpy


def run(*, quick: bool = False, with_batch: bool = True) -> dict[str, object]:
    n, repeats = (2000, 3) if quick else (10_000, 15)
    print("predict, update and step() run " + ("the C extension fusion.core._single" if single.COMPILED else
          "numba's twins: this install has no C extension (built without a C compiler?)"))
    out: dict[str, object] = {
        "step_compiled_c": single.COMPILED,
        "kf": table("KF predict+update, 4-state CV, 2-D position", kf_setups, n=n, repeats=repeats),
        "ekf": table("EKF predict+update, radar2d (range, bearing)", ekf_setups, n=n, repeats=repeats),
    }
    for key, name in (("kf", "fusion KF"), ("kf", "fusion KF step()"), ("ekf", "fusion EKF"),
                      ("ekf", "fusion EKF step()")):
        r = out[key][name]  # type: ignore[index]
        print(f"goal: {name} (inputs validated) >= {GOAL:.0f}x filterpy: median {r['ratio_median']:.2f}x "
              f"[{r['ratio_min']:.2f}, {r['ratio_max']:.2f}] -> {'met' if r['ratio_median'] >= GOAL else 'NOT met'}")
    if with_batch:
        out["batch_us_per_track_step"] = batch(repeats=repeats)
    return out


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="2000 steps x 3 repeats")
    ap.add_argument("--no-batch", action="store_true", help="skip the stacked-kernel table")
    args = ap.parse_args()
    run(quick=args.quick, with_batch=not args.no_batch)
