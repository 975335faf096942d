"""The README's commands, timed as a user runs them: a fresh process each, a fresh cache folder.

Prints one row per command (whole-process seconds, exit status, the command's last line) so the
timings the README quotes can be checked and kept current:

    python benchmarks/readme_timings.py [--repeat 1]

The commands are read from README.md itself (every ``.venv/bin/matremap ...`` line of a ``sh`` block
that writes to ``out/``), so the table follows the README when it changes.
"""

from __future__ import annotations

import argparse
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    text = (ROOT / "README.md").read_text()
    out = []
    for block in re.findall(r"```sh\n(.*?)```", text, re.S):
        for line in block.splitlines():
            m = re.search(r"(\.venv/bin/matremap (remap|fit) .*)$", line)
            if m:
                out.append(m.group(1))
    return out


def run(command: str, workdir: Path, env: dict[str, str]) -> tuple[float, int, str]:
    argv = shlex.split(command)
    argv[0] = str(Path(sys.executable).parent / "matremap")
    t0 = time.perf_counter()
    p = subprocess.run(argv, cwd=workdir, env=env, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    last = (p.stdout.strip().splitlines() or p.stderr.strip().splitlines() or [""])[-1]
    return seconds, p.returncode, last


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=1)
    args = ap.parse_args()
    print(f"{'seconds':>8} {'exit':>4}  command / last line")
    for command in readme_commands():
        for _ in range(args.repeat):
            with tempfile.TemporaryDirectory() as tmp:
                work = Path(tmp)
                (work / "examples").symlink_to(ROOT / "examples")
                env = {**os.environ, "MATREMAP_CACHE_DIR": str(work / "cache"), "MATREMAP_CACHE": str(work / "cache")}
                seconds, code, last = run(command, work, env)
            print(f"{seconds:8.1f} {code:>4}  {command[:110]}\n{'':15}{last[:110]}")


if __name__ == "__main__":
    main()
