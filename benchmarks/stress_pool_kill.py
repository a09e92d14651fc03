"""Kill a detection worker at a random moment while results stream back: does the caller hear of it, or hang?

    PYTHONPATH=. .venv/bin/python benchmarks/stress_pool_kill.py [--rounds 30] [--result-kb 300]

Each round starts a fork-server pool of 2 workers (as ``worker_pool`` does), queues 400 tasks that each return
``--result-kb`` of bytes (a detection result carries the half-size picture: ~300 KB at 1280x960), waits a
random
0-50 ms and SIGKILLs one worker, the out-of-memory killer's stand-in. A round "settled" when every future is
done within 10 s (BrokenProcessPool for the unfinished ones), "hung" when some never are: the pool's manager
thread blocks reading a half-written result. Two paths, rounds taking turns:
  * pipe: ``pool.submit`` (ProcessPoolExecutor as shipped: the result pickled into its pipe);
  * file: ``worker_pool.submit`` (the result written to a file, only its name through the pipe).
A robustness check, not a timing: nothing here is asserted, the counts are printed.
"""

from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import random
import signal
import sys
import time
from concurrent.futures import ProcessPoolExecutor, wait
from pathlib import Path

from machine import cpu_model, load_1min

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from calibctl.core.capture import worker_pool  # noqa: E402

TASKS = 400
SETTLE_S = 10.0


def result_of(size: int) -> bytes:
    return bytes(size)


def one_round(path: str, size: int, rng: random.Random) -> bool:
    """True when every future settled after the kill."""
    pool = ProcessPoolExecutor(2, mp_context=worker_pool._mp_context())  # noqa: SLF001 - the pool's own start method
    try:
        pool.submit(int).result(timeout=120)
        submit = pool.submit if path == "pipe" else (lambda fn, *a: worker_pool.submit(pool, fn, *a))
        futures = [submit(result_of, size) for _ in range(TASKS)]
        time.sleep(rng.uniform(0.0, 0.05))
        os.kill(next(iter(pool._processes)), signal.SIGKILL)  # noqa: SLF001 - the stand-in for the OOM killer
        _, not_done = wait(futures, timeout=SETTLE_S)
        return not not_done
    finally:
        for process in list(pool._processes.values()):  # noqa: SLF001 - a hung pool cannot shut down by itself
            process.kill()
        pool.shutdown(wait=False, cancel_futures=True)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--result-kb", type=int, default=300)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    size = args.result_kb * 1024
    print(
        f"{dt.datetime.now(dt.UTC):%Y-%m-%d %H:%M} UTC, {cpu_model()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}, load {load_1min():.2f}; {args.rounds} rounds per path, "
        f"{TASKS} results of {args.result_kb} KB, one worker of 2 killed 0-50 ms in"
    )
    hung = {"pipe": 0, "file": 0}
    for _ in range(args.rounds):
        for path in hung:
            hung[path] += not one_round(path, size, rng)
    for path, count in hung.items():
        print(f"  {path}: settled {args.rounds - count}, hung {count}")
    print(f"load after {load_1min():.2f}")
    os._exit(0)  # a hung pool's manager thread would keep the interpreter from exiting


if __name__ == "__main__":
    main()
