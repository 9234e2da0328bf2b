"""Calibration study: shipped wrist-ik on subjects of another size (0.8, 1.2) whose markers sit
up to 15 mm (uniform, per axis) from the body model's placement; angle MSE (rad², all frames
with output) nominal vs uncalibrated vs calibrated (measured on trials with the same noise)
vs a perfect calibration (measured on clean trials). ~1 min.

A second table does the same for the methods a real session allows (``ikid.calibration.
calibrate_neutral``): landmarks (epicondyles and styloids, 1 mm noise each) + 100 neutral frames,
and neutral frames alone, with the hand cluster also turned about the hand's long axis (0°, 90°,
180°: a plate mounted any way round); the neutral method keeps the body model's forearm
placement, so its error is the forearm markers' misplacement; functional (``calibrate_functional``):
the same neutral frames plus 4 s of the wrist circling through flexion and deviation, pronation held
at 0° or at 30° (the axes fitted by least squares). ~2 min more.

    .venv/bin/python examples/calibration_study.py
"""

import numpy as np

import ikid
from ikid import _native
from ikid.pipeline import run_model

SHOULDER = 0.3


def single(j, n=4000, amp=0.6):
    q = np.zeros((n, 3))
    q[:, j] = amp * np.sin(np.linspace(0, 2 * np.pi, n))
    return q


def main() -> None:
    rng = np.random.default_rng(5)
    model = ikid.load("wrist-ik")
    print(
        "| trial seed | size | noise | nominal | uncalibrated | calibrated | perfect "
        "calibration | calibrated / nominal |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for seed in (9100, 9101):
        q = ikid.simulate("random", seed=seed, duration=20, shoulder_flexion=SHOULDER).q
        for scale in (0.8, 1.2):
            shift = rng.uniform(-0.015, 0.015, (6, 3))
            for noise in (0.0, 0.01):

                def markers(qq, s, shift=shift, scale=scale, noise=noise):
                    m = ikid.forward_markers(qq, SHOULDER, scale, scale**3, shift)
                    return _native.noise_uniform(m, noise, s) if noise else m

                def mse(frames, cal=None, q=q):
                    run = run_model(model, frames, np.arange(len(frames)) / 1000.0, calibration=cal)
                    return float(np.mean((run.values - q[run.frame]) ** 2))

                def calibration(with_noise, shift=shift, scale=scale):
                    def exact(qq, s):
                        return ikid.forward_markers(qq, SHOULDER, scale, scale**3, shift)

                    f = markers if with_noise else exact
                    return ikid.calibrate(
                        f(np.zeros((2000, 3)), 2),
                        {"ra_wr_s_p": f(single(0), 3), "ra_wr_e_f": f(single(1), 4)},
                    )

                nominal_frames = ikid.forward_markers(q, SHOULDER)
                nominal = mse(_native.noise_uniform(nominal_frames, noise, 1) if noise else nominal_frames)
                moved = markers(q, 1)
                cal = mse(moved, calibration(True))
                print(
                    f"| {seed} | {scale} | {noise:.0%} | {nominal:.3g} | {mse(moved):.3g} | {cal:.3g} | "
                    f"{mse(moved, calibration(False)):.3g} | {cal / nominal:.2f} |",
                    flush=True,
                )


#: Landmarks in the default forearm's anatomical frame (m): lateral and medial epicondyle, radial
#: and ulnar styloid.
LANDMARKS = np.array([[0.0, 0.26, 0.035], [0.0, 0.26, -0.035], [0.0, 0.005, 0.03], [0.0, 0.005, -0.03]])


def session_methods() -> None:
    from ikid.calibration import calibrate_functional, calibrate_neutral

    rng = np.random.default_rng(6)
    model = ikid.load("wrist-ik")
    offsets = np.array([m["offset"] for m in ikid.body_model()["markers"]])
    print()
    print(
        "| size | hand cluster turn | noise | nominal | uncalibrated | landmarks | neutral only | functional "
        "| functional, pronation held at 30° |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    t = np.linspace(0.0, 2 * np.pi, 4000)
    circles = np.stack([0 * t, 0.6 * np.sin(2 * t) + 0.2 * np.cos(t), 0.25 * np.cos(3 * t)], axis=1)
    q = ikid.simulate("random", seed=9102, duration=20, shoulder_flexion=SHOULDER).q
    for scale in (0.8, 1.2):
        for turn in (0.0, 90.0, 180.0):
            shift = rng.uniform(-0.015, 0.015, (6, 3))
            c, s = np.cos(np.radians(turn)), np.sin(np.radians(turn))
            rot = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
            for m in range(3, 6):
                shift[m] = rot @ (offsets[m] + shift[m]) - offsets[m]
            for noise in (0.0, 0.01):

                def markers(qq, seed, shift=shift, scale=scale, noise=noise):
                    m = ikid.forward_markers(qq, SHOULDER, scale, scale**3, shift)
                    return _native.noise_uniform(m, noise, seed) if noise else m

                def mse(frames, cal=None, q=q):
                    run = run_model(model, frames, np.arange(len(frames)) / 1000.0, calibration=cal)
                    return float(np.mean((run.values - q[run.frame]) ** 2))

                points = []
                for landmark in LANDMARKS:
                    probe = np.zeros((6, 3))
                    probe[0] = scale * (landmark - offsets[0])
                    points.append(ikid.forward_markers(np.zeros((1, 3)), SHOULDER, scale, 1.0, probe)[0, :3])
                landmarks = np.tile(np.concatenate(points), (100, 1))
                if noise:
                    landmarks = landmarks + rng.normal(0.0, 0.001, landmarks.shape)
                neutral = markers(np.zeros((100, 3)), 2)
                nominal_frames = ikid.forward_markers(q, SHOULDER)
                nominal = mse(_native.noise_uniform(nominal_frames, noise, 1) if noise else nominal_frames)
                moved = markers(q, 1)
                by_landmarks = mse(moved, calibrate_neutral(neutral, landmarks))
                by_neutral = mse(moved, calibrate_neutral(neutral))
                by_motion = [
                    mse(moved, calibrate_functional(neutral, markers(circles + [held, 0.0, 0.0], 3)))
                    for held in (0.0, np.radians(30.0))
                ]
                print(
                    f"| {scale} | {turn:.0f}° | {noise:.0%} | {nominal:.3g} | {mse(moved):.3g} | "
                    f"{by_landmarks:.3g} | {by_neutral:.3g} | {by_motion[0]:.3g} | {by_motion[1]:.3g} |",
                    flush=True,
                )


if __name__ == "__main__":
    main()
    session_methods()
