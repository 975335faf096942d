"""Time every command of the README as a user runs it: each in a fresh process with a fresh, empty
cache (``MATREMAP_CACHE`` in a new temporary folder: the numerically integrated tables and glTF image
copies are built as on a new install), from a scratch folder where ``examples/`` and ``.venv`` are the
repository's, so ``out/...`` lands there. The commands are read from the README's ``sh`` blocks (a line
that runs ``.venv/bin/matremap``, after any ``&&``), so the table follows the README as it changes; the
install and the test suite are not timed (``--tests`` times the README's test command too, ~4 min).

    .venv/bin/python benchmarks/readme_timings.py            # the table, with the machine and its load
    .venv/bin/python benchmarks/readme_timings.py --repeat 3 # the best of three runs of each
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def readme_commands(text: str, tests: bool = False) -> list[str]:
    """The matremap command lines of the README's ``sh`` blocks, in order, each once."""
    found: list[str] = []
    for block in re.findall(r"```sh\n(.*?)```", text, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            for part in line.split("&&"):
                part = part.strip()
                is_test = "pytest" in part
                if (part.startswith(".venv/bin/matremap ") or (tests and is_test)) and part not in found:
                    found.append(part)
    return found


def run(command: str, scratch: Path) -> tuple[float, int, str]:
    """Seconds, exit status and last output line of one command, in a fresh process with a fresh cache."""
    with tempfile.TemporaryDirectory(prefix="matremap-cache-") as cache:
        env = {**os.environ, "MATREMAP_CACHE": cache, "PYTHONPATH": str(ROOT / "src")}
        t0 = time.perf_counter()
        done = subprocess.run(shlex.split(command), cwd=scratch, env=env, capture_output=True, text=True)
        seconds = time.perf_counter() - t0
    lines = done.stdout.strip().splitlines() or done.stderr.strip().splitlines()  # the result line, else the error
    return seconds, done.returncode, lines[-1] if lines else ""


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    load = ", ".join(f"{x:.1f}" for x in os.getloadavg())
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}; load average {load}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=1, help="runs of each command; the best is shown (default 1)")
    ap.add_argument("--tests", action="store_true", help="also time the README's test command (~4 min)")
    args = ap.parse_args(argv)
    commands = readme_commands(README.read_text(), tests=args.tests)
    print(f"machine: {machine()}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="matremap-readme-") as tmp:
        scratch = Path(tmp)
        for name in ("examples", ".venv", ".venv-bpy", "src", "tests", "pyproject.toml"):
            if (ROOT / name).exists():
                (scratch / name).symlink_to(ROOT / name)
        for command in commands:
            runs = []
            for _ in range(args.repeat):
                runs.append(run(command, scratch))
                subprocess.run(["rm", "-rf", str(scratch / "out")], check=False)
            seconds, code, last = min(runs)
            rows.append((command, seconds, code, last))
            print(f"{seconds:7.1f} s  exit {code}  {command}", flush=True)
            print(f"{'':19}{last[:150]}", flush=True)
    print("\n| command | seconds | exit |\n|---|---:|---:|")
    for command, seconds, code, _ in rows:
        print(f"| `{command.replace('.venv/bin/', '')}` | {seconds:.1f} | {code} |")
    print(f"\nmachine: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
