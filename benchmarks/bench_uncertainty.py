"""Is the reported uncertainty honest? z = (estimate - truth) / reported sigma over seeded sessions.

Each session: the production model (k1k2: CALIB_FIX_K3 | CALIB_ZERO_TANGENT_DIST |
CALIB_FIX_ASPECT_RATIO), a true camera that model can represent (fx = fy = 800 px, c = (321.3,
238.7), k1 = -0.2814, k2 = 0.0977, 640 x 480), 15-20 views (15 + i % 6) of a 9 x 6 board tilted
20-40 deg in random directions, 0.2 px Gaussian corner noise, seed = SEED_BASE + i. If sigma is
honest, z has mean 0 and standard deviation 1. The issue's bar: |mean| <= 0.3 and 0.7 <= std <= 1.5
over >= 30 sessions, for fx and for cx.

Run: python benchmarks/bench_uncertainty.py [N_SESSIONS] [SEED_BASE]   (default 30, 0)
Prints markdown: machine, date, summary, and the per-session table.
"""

from __future__ import annotations

import platform
import sys
import time
from dataclasses import dataclass
from datetime import date

import cv2
import numpy as np

from calibctl.core.intrinsics.solve import solve_intrinsics
from calibctl.core.synth.corners import synthesize_session

K_TRUE = np.array([[800.0, 0.0, 321.3], [0.0, 800.0, 238.7], [0.0, 0.0, 1.0]])
D_TRUE = np.array([-0.2814, 0.0977, 0.0, 0.0, 0.0])
SIZE = (640, 480)


@dataclass(frozen=True)
class SessionResult:
    seed: int
    n_views: int
    fx: float
    sigma_fx: float
    cx: float
    sigma_cx: float
    rms_px: float

    @property
    def z_fx(self) -> float:
        return (self.fx - K_TRUE[0, 0]) / self.sigma_fx

    @property
    def z_cx(self) -> float:
        return (self.cx - K_TRUE[0, 2]) / self.sigma_cx


def run_session(seed: int, n_views: int) -> SessionResult:
    ses = synthesize_session(K_TRUE, D_TRUE, SIZE, n_views=n_views, seed=seed)
    sol = solve_intrinsics(ses.object_points_per_view, ses.image_points_per_view, SIZE, "k1k2")
    return SessionResult(seed, n_views, sol.fx, sol.sigma["fx"], sol.cx, sol.sigma["cx"], sol.rms_px)


def run(n_sessions: int, seed_base: int) -> list[SessionResult]:
    return [run_session(seed_base + i, 15 + i % 6) for i in range(n_sessions)]


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 30
    base = int(sys.argv[2]) if len(sys.argv) > 2 else 0
    t0 = time.perf_counter()
    results = run(n, base)
    elapsed = time.perf_counter() - t0
    z_fx = np.array([r.z_fx for r in results])
    z_cx = np.array([r.z_cx for r in results])
    print(f"# Uncertainty honesty — {n} sessions, seeds {base}..{base + n - 1}\n")
    print(
        f"{date.today()}, {platform.node()} {platform.machine()}, {platform.python_version()}, "
        f"OpenCV {cv2.__version__}, numpy {np.__version__}; {elapsed:.1f} s "
        f"({1000 * elapsed / n:.0f} ms per session)\n"
    )
    print("| quantity | mean z | std z | max abs z | bar |")
    print("|---|---|---|---|---|")
    for name, z in (("fx", z_fx), ("cx", z_cx)):
        ok = abs(z.mean()) <= 0.3 and 0.7 <= z.std(ddof=1) <= 1.5
        print(
            f"| {name} | {z.mean():+.3f} | {z.std(ddof=1):.3f} | {np.abs(z).max():.2f} | "
            f"{'pass' if ok else 'FAIL'} |"
        )
    if n >= 60:
        print(
            "\nBlocks of 30 consecutive sessions (how much a 30-session mean moves by chance; "
            "its standard error is 1/sqrt(30) = 0.18):\n"
        )
        print("| block | mean z fx | std z fx | mean z cx | std z cx |")
        print("|---|---|---|---|---|")
        for b in range(n // 30):
            zf, zc = z_fx[30 * b : 30 * b + 30], z_cx[30 * b : 30 * b + 30]
            print(
                f"| {base + 30 * b}..{base + 30 * b + 29} | {zf.mean():+.3f} | {zf.std(ddof=1):.3f} "
                f"| {zc.mean():+.3f} | {zc.std(ddof=1):.3f} |"
            )
    print("\n| seed | views | fx px | sigma fx px | z fx | cx px | sigma cx px | z cx | RMS px |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in results:
        print(
            f"| {r.seed} | {r.n_views} | {r.fx:.3f} | {r.sigma_fx:.3f} | {r.z_fx:+.2f} | {r.cx:.3f} "
            f"| {r.sigma_cx:.3f} | {r.z_cx:+.2f} | {r.rms_px:.4f} |"
        )


if __name__ == "__main__":
    main()
