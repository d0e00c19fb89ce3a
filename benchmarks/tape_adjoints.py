"""Warp's tape against the hand-written adjoints of the ground laws (issue 31: `wp.Tape` where it is right and no
slower): for each law — the explicit one (kernels/contact.py `ground_contact_kernel` + `friction_kernel`) and the
implicit one under Coulomb's law and the tanh law (`implicit_contact_kernel`) — at N random points in and out of
contact, the adjoints p̂, û of f̂ · f by `wp.Tape` (the forward recorded, then taken back) and by the hand-written
kernels (kernels/adjoint_contact.py), each against a central difference of f̂ · f along a random direction of
(p, u), and their times side by side in one process.

    wavewarp bench tape_adjoints --device cpu --points 20000 --out benchmarks/results/tape_adjoints

Writes tape_adjoints_<device>.json.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from datetime import date

if __package__ in (None, ""):
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

import numpy as np  # noqa: E402
import warp as wp  # noqa: E402

from wavewarp.device import describe_device, device_tag, resolve_device  # noqa: E402
from wavewarp.io import write_json  # noqa: E402
from wavewarp.kernels.adjoint_contact import ground_adjoint_kernel, implicit_law_adjoint_kernel  # noqa: E402
from wavewarp.kernels.contact import friction_kernel, ground_contact_kernel  # noqa: E402
from wavewarp.kernels.implicit_contact import implicit_contact_kernel  # noqa: E402

LAWS = ("explicit", "implicit-coulomb", "implicit-tanh")
K, BETA, MU, K_F, SCALE, DT = 1e3, 5.0, 0.5, 10.0, 0.1, 1e-3  # the laws' parameters (k_f = ∞ for Coulomb's)
STEP = 1e-6  # the central difference's step along the random direction


class LawCase:
    """One law at `points` random points (z from 2% of R below the ground to 0.5% above, slip speeds ~0.05): its
    forward f(p, u) recorded on a tape or evaluated plainly, and its hand-written adjoint."""

    def __init__(self, law: str, points: int, seed: int = 0, device=None):
        self.law, self.n, self.device = law, points, device
        rng = np.random.default_rng(seed)
        vectors = {"p": np.c_[rng.normal(size=(points, 2)), rng.uniform(-0.02, 0.005, points)],
                   "u": rng.normal(scale=0.05, size=(points, 3)), "f_hat": rng.normal(size=(points, 3)),
                   "dp": rng.normal(size=(points, 3)), "du": rng.normal(size=(points, 3))}  # fmt: skip
        with wp.ScopedDevice(device):
            self.a = {name: wp.array(value, dtype=wp.vec3d, requires_grad=name in ("p", "u"))
                      for name, value in vectors.items()}  # fmt: skip
            self.response = wp.array(rng.uniform(0.5, 2.0, points), dtype=wp.float64)
            self.response_move = rng.normal(size=points)
            self.response_hat = wp.zeros(points, dtype=wp.float64)
            self.normal = wp.zeros(points, dtype=wp.float64, requires_grad=True)
            self.forces = wp.zeros(points, dtype=wp.vec3d, requires_grad=True)
            self.p_hat, self.u_hat = wp.zeros(points, dtype=wp.vec3d), wp.zeros(points, dtype=wp.vec3d)
            self.gradient = wp.zeros(5, dtype=wp.float64)
            self.body = wp.zeros(1, dtype=wp.vec3d)
        k_f = np.inf if law == "implicit-coulomb" else K_F
        self.laws = [wp.float64(v) for v in (SCALE, DT, K, BETA, MU, k_f)]

    def forward(self, p, u) -> None:
        self.forces.zero_()
        if self.law == "explicit":
            wp.launch(ground_contact_kernel, self.n, inputs=[p, u, wp.float64(K), wp.float64(BETA)],
                      outputs=[self.normal, self.forces], device=self.device)  # fmt: skip
            wp.launch(friction_kernel, self.n, inputs=[u, self.normal, wp.float64(MU), wp.float64(K_F)],
                      outputs=[self.forces], device=self.device)  # fmt: skip
        else:
            wp.launch(implicit_contact_kernel, self.n, inputs=[p, u, self.response, *self.laws, self.body],
                      outputs=[self.normal, self.forces], device=self.device)  # fmt: skip

    def record(self) -> wp.Tape:
        tape = wp.Tape()
        with tape:
            self.forward(self.a["p"], self.a["u"])
        return tape

    def tape_backward(self, tape) -> tuple:
        """p̂, û by the tape (zeroed after)."""
        tape.backward(grads={self.forces: self.a["f_hat"]})
        result = self.a["p"].grad.numpy().copy(), self.a["u"].grad.numpy().copy()
        tape.zero()
        return result

    def hand(self) -> tuple:
        """p̂, û by the hand-written kernel (it evaluates the law's forward itself); the implicit laws' r̂ in
        `response_hat`."""
        p, u, f_hat = self.a["p"], self.a["u"], self.a["f_hat"]
        self.p_hat.zero_()
        self.response_hat.zero_()
        if self.law == "explicit":
            wp.launch(ground_adjoint_kernel, self.n, inputs=[p, u, f_hat, *[wp.float64(v) for v in (K, BETA, MU, K_F)]],
                      outputs=[self.p_hat, self.u_hat, self.gradient], device=self.device)  # fmt: skip
        else:
            wp.launch(implicit_law_adjoint_kernel, self.n, inputs=[p, u, self.response, *self.laws, f_hat],
                      outputs=[self.u_hat, self.p_hat, self.gradient, self.response_hat],
                      device=self.device)  # fmt: skip
        return self.p_hat.numpy().copy(), self.u_hat.numpy().copy()

    def directional_difference(self) -> float:
        """(f̂·f(p + εdp, u + εdu) - f̂·f(p - εdp, u - εdu)) / 2ε."""
        values = []
        for sign in (1.0, -1.0):
            shifted = [wp.array(self.a[name].numpy() + sign * STEP * self.a["d" + name].numpy(), dtype=wp.vec3d,
                                device=self.device) for name in ("p", "u")]  # fmt: skip
            self.forward(*shifted)
            values.append(float(np.sum(self.forces.numpy() * self.a["f_hat"].numpy())))
        return (values[0] - values[1]) / (2.0 * STEP)

    def response_difference(self) -> float:
        """(f̂·f(r + εdr) - f̂·f(r - εdr)) / 2ε of the implicit laws, dr a random move of the points' responses."""
        base, values = self.response.numpy().copy(), []
        for sign in (1.0, -1.0):
            self.response.assign(base + sign * STEP * self.response_move)
            self.forward(self.a["p"], self.a["u"])
            values.append(float(np.sum(self.forces.numpy() * self.a["f_hat"].numpy())))
        self.response.assign(base)
        return (values[0] - values[1]) / (2.0 * STEP)

    def along_direction(self, adjoint: tuple) -> float:
        """p̂·dp + û·du."""
        return float(np.sum(adjoint[0] * self.a["dp"].numpy()) + np.sum(adjoint[1] * self.a["du"].numpy()))


def seconds(call, device, repeats: int) -> float:
    call()
    wp.synchronize_device(device)
    start = time.perf_counter()
    for _ in range(repeats):
        call()
    wp.synchronize_device(device)
    return (time.perf_counter() - start) / repeats


def measure(law: str, points: int, device, repeats: int) -> dict:
    case = LawCase(law, points, device=device)
    tape = case.record()
    taped, hand = case.tape_backward(tape), case.hand()
    reference = case.directional_difference()
    scale = max(np.abs(hand[0]).max(), np.abs(hand[1]).max())
    return {"law": law, "points": points,
            "tape_against_hand": max(np.abs(taped[0] - hand[0]).max(), np.abs(taped[1] - hand[1]).max()) / scale,
            "tape_against_difference": abs(case.along_direction(taped) - reference) / abs(reference),
            "hand_against_difference": abs(case.along_direction(hand) - reference) / abs(reference),
            "tape_seconds": seconds(lambda: case.tape_backward(case.record()), device, repeats),
            "tape_backward_seconds": seconds(lambda: case.tape_backward(tape), device, repeats),
            "hand_seconds": seconds(case.hand, device, repeats)}  # fmt: skip


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="wavewarp bench tape_adjoints", description=__doc__.split("\n\n")[0])
    parser.add_argument("--device", default=None)
    parser.add_argument("--points", type=int, default=20000)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--out", default=".")
    args = parser.parse_args(argv)
    device = resolve_device(args.device)
    rows = [measure(law, args.points, device, args.repeats) for law in LAWS]
    for row in rows:
        print(f"{row['law']:<17} tape vs hand {row['tape_against_hand']:.1e}; against the difference: tape "
              f"{row['tape_against_difference']:.1e}, hand {row['hand_against_difference']:.1e}; time: tape "
              f"{row['tape_seconds'] * 1e3:.3g} ms (backward alone {row['tape_backward_seconds'] * 1e3:.3g} ms), hand "
              f"{row['hand_seconds'] * 1e3:.3g} ms")  # fmt: skip
    result = {"benchmark": "tape_adjoints", "date": date.today().isoformat(), **describe_device(device), "rows": rows}
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, f"tape_adjoints_{device_tag(device)}.json")
    write_json(path, result)
    print(f"wrote {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
