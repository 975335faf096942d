"""Regenerate src/matremap/dialects/mitsuba3_conductors.py from the installed Mitsuba 3.

Loads a ``roughconductor`` with each named ``material`` in ``scalar_rgb`` and reads the RGB ``eta`` and
``k`` Mitsuba converted its spectral data to. Usage: ``python tools/mitsuba3_conductors.py``.
"""

from __future__ import annotations

from pathlib import Path

import mitsuba as mi

from matremap.dialects.mitsuba3 import CONDUCTORS

OUT = Path(__file__).resolve().parents[1] / "src" / "matremap" / "dialects" / "mitsuba3_conductors.py"


def main() -> None:
    mi.set_variant("scalar_rgb")
    rows = []
    for name in CONDUCTORS:
        if name == "none":
            continue
        p = mi.traverse(mi.load_dict({"type": "roughconductor", "material": name}))
        eta = ", ".join(f"{float(x):.6g}" for x in p["eta.value"])
        k = ", ".join(f"{float(x):.6g}" for x in p["k.value"])
        rows.append(f'    "{name}": (({eta}), ({k})),')
    head, _, _ = OUT.read_text().partition("CONDUCTOR_RGB")
    OUT.write_text(
        head
        + "CONDUCTOR_RGB: dict[str, tuple[tuple[float, float, float], tuple[float, float, float]]] = {\n"
        + "\n".join(rows)
        + "\n}\n"
    )
    print(f"{len(rows)} conductors ({mi.__version__}) -> {OUT}")


if __name__ == "__main__":
    main()
