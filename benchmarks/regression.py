"""Parametric regression vs the SVR baseline (paper §5): extrapolation, hue, speed, authors' table.

1. sub-box: sweep Ward (variant ward, no diffuse) -> AS over alpha 0.02..0.99 x rho_s 0.02..0.3
   (30 x 15, two-stage), train both methods on rho_s <= 0.12 and alpha <= 0.5 only, and measure
   their RMSE on alpha_2 and F0 outside that box (target: parametric <= 1/2 of SVR);
2. hue: apply both (trained on the whole sweep) to coloured rho_s and report the change of HSV
   hue of F0 against the input (target < 0.5 deg for parametric);
3. speed: apply each to a 4096^2 alpha map and RGB rho_s map (target: parametric >= 100x faster);
4. the authors' grid: held-out RMSE of the parametric transform in % of the range of alpha_2 and
   F0 (target < 1 %), from our sweep and fitted directly to their published table;
5. plots in the paper's style, written to --plots.

    python benchmarks/regression.py [--size 64] [--workers 2] [--plots docs/img/regression]

Sweep databases are cached in a temporary folder (--cache) and reused by later runs.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import tempfile
import time
from pathlib import Path

import numpy as np

from matremap.core.material import Material
from matremap.core.scene import Scene
from matremap.errors import MatremapError
from matremap.regress import parametric
from matremap.regress.data import TrainingData, load_training_data
from matremap.regress.transform import Transform, _evaluate, transform_from_data
from matremap.sweep.executors import make_executor
from matremap.sweep.grid import parse_grid
from matremap.sweep.run import SweepConfig, run_sweep

ROOT = Path(__file__).resolve().parents[1]
TABLE = ROOT / "tests" / "data" / "reference" / "mitsuba-ward2mitsuba-as.csv"
SOURCE = Material.create("mitsuba06:ward", {"variant": "ward", "diffuseReflectance": 0.0})
GRID_BOX = "alpha=0.02:0.99:30,specularReflectance=0.02:0.3:15"
GRID_AUTHORS = "alpha=0.005:0.99:35,specularReflectance=0.02:0.232413793103:23"
BOX_ALPHA, BOX_RHO = 0.5, 0.12
COLOURS = [
    (0.1, 0.05, 0.02),
    (0.02, 0.08, 0.12),
    (0.12, 0.1, 0.03),
    (0.05, 0.02, 0.1),
    (0.25, 0.12, 0.04),
    (0.03, 0.2, 0.06),
]
HUE_ALPHAS = (0.05, 0.2, 0.4, 0.7, 0.9)


# -- helpers ---------------------------------------------------------------------------------------
def sweep(grid_text: str, size: int, workers: int, cache: Path) -> tuple[Path, float, int]:
    """A Ward -> AS sweep database (cached: a rerun only finishes what is missing)."""
    config = SweepConfig(
        source=SOURCE, target="mitsuba06:pbr", fix={"distribution": "as"}, scene=Scene(resolution=size)
    )
    grid = parse_grid(grid_text, SOURCE.spec)
    db = cache / f"w2as-{hashlib.sha1(grid_text.encode()).hexdigest()[:10]}-{size}.sqlite"
    t = time.perf_counter()
    for attempt in (0, 1):
        try:
            with make_executor(workers=workers) as (ex, _):
                summary = run_sweep(config, grid, str(db), ex, in_flight=2 * workers)
            break
        except MatremapError:  # a cache written by another configuration or version: start again
            if attempt:
                raise
            db.unlink(missing_ok=True)
    return db, time.perf_counter() - t, summary.done


def timed_learn(data: TrainingData, method: str) -> tuple[Transform, float]:
    t = time.perf_counter()
    tr = transform_from_data(data, method)
    return tr, time.perf_counter() - t


def predict(tr: Transform, alpha: np.ndarray, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    out, _ = tr.apply({"alpha": alpha, "specularReflectance": rho})
    return out["alpha"], out["F0"]


def rmse(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(a) - np.asarray(b)) ** 2)))


def hsv_hue(rgb: np.ndarray) -> np.ndarray:
    """HSV hue in degrees [0, 360) of RGB triples [..., 3]."""
    r, g, b = np.moveaxis(np.asarray(rgb, dtype=float), -1, 0)
    mx, mn = np.maximum(np.maximum(r, g), b), np.minimum(np.minimum(r, g), b)
    c = np.where(mx - mn > 0, mx - mn, 1.0)
    h = np.where(mx == r, ((g - b) / c) % 6, np.where(mx == g, (b - r) / c + 2, (r - g) / c + 4))
    return np.where(mx - mn > 0, 60.0 * h, 0.0)


def hue_diff(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.abs((a - b + 180.0) % 360.0 - 180.0)


def svs(tr: Transform) -> str:
    return ", ".join(
        f"{q}: C={m['C']:g} gamma={m['gamma']:g} eps={m['epsilon']:g} {len(m['support_vectors'])} SVs of {m['n_train']}"
        for q, m in tr.mappings.items()
        if m["kind"] == "svr"
    )


# -- the experiments ---------------------------------------------------------------------------------
def subbox(data: TrainingData) -> tuple[Transform, Transform, np.ndarray]:
    a, s = data.x["roughness"], data.x["reflectance"][:, 0]
    inbox = (a <= BOX_ALPHA + 1e-9) & (s <= BOX_RHO + 1e-9)
    train = data.subset(inbox)
    tp, sp = timed_learn(train, "parametric")
    ts, ss = timed_learn(train, "svr")
    print(
        f"\n## 1. extrapolation: trained on alpha <= {BOX_ALPHA}, rho_s <= {BOX_RHO} ({inbox.sum()} points; "
        f"learning {sp:.1f} s parametric, {ss:.1f} s SVR), tested on the {(~inbox).sum()} points outside"
    )
    print(f"   SVR picked {svs(ts)}")
    print(
        f"{'test region':<34} {'n':>4} {'alpha2 param':>12} {'alpha2 SVR':>11} {'ratio':>6} "
        f"{'F0 param':>10} {'F0 SVR':>10} {'ratio':>6}"
    )
    regions = {
        "inside (training points)": inbox,
        "outside the box (all)": ~inbox,
        "alpha > 0.5, rho_s <= 0.12": (a > BOX_ALPHA + 1e-9) & (s <= BOX_RHO + 1e-9),
        "alpha <= 0.5, rho_s > 0.12": (a <= BOX_ALPHA + 1e-9) & (s > BOX_RHO + 1e-9),
        "alpha > 0.5, rho_s > 0.12": (a > BOX_ALPHA + 1e-9) & (s > BOX_RHO + 1e-9),
    }
    pa, pf = predict(tp, a, data.x["reflectance"])
    sa, sf = predict(ts, a, data.x["reflectance"])
    ya, yf = data.y["roughness"], data.y["reflectance"]
    for label, m in regions.items():
        e = [rmse(pa[m], ya[m]), rmse(sa[m], ya[m]), rmse(pf[m], yf[m]), rmse(sf[m], yf[m])]
        print(
            f"{label:<34} {m.sum():>4} {e[0]:12.5f} {e[1]:11.5f} {e[0] / e[1]:6.2f} "
            f"{e[2]:10.5f} {e[3]:10.5f} {e[2] / e[3]:6.2f}"
        )
    return tp, ts, inbox


def hue(tp: Transform, ts: Transform, tp_box: Transform, ts_box: Transform) -> None:
    print(
        f"\n## 2. hue shift: |HSV hue(F0) - HSV hue(rho_s)| in degrees, {len(COLOURS)} coloured rho_s x "
        f"alpha in {HUE_ALPHAS}; transforms learned on the whole sweep, and on the box only (extrapolating)"
    )
    alpha = np.repeat(np.array(HUE_ALPHAS), len(COLOURS))
    rho = np.tile(np.array(COLOURS), (len(HUE_ALPHAS), 1))
    h0 = hsv_hue(rho)
    print(
        f"{'rho_s':<20} {'hue in':>7} {'param max':>10} {'SVR max':>9} {'SVR at alpha':>13} "
        f"{'box: param':>11} {'box: SVR':>9}"
    )
    shifts = {}
    for name, tr in (("parametric", tp), ("SVR", ts), ("box parametric", tp_box), ("box SVR", ts_box)):
        shifts[name] = hue_diff(hsv_hue(predict(tr, alpha, rho)[1]), h0).reshape(len(HUE_ALPHAS), len(COLOURS))
    for j, c in enumerate(COLOURS):
        i = int(np.argmax(shifts["SVR"][:, j]))
        print(
            f"{str(c):<20} {h0[j]:7.1f} {shifts['parametric'][:, j].max():10.2e} {shifts['SVR'][:, j].max():9.3f} "
            f"{HUE_ALPHAS[i]:13g} {shifts['box parametric'][:, j].max():11.2e} {shifts['box SVR'][:, j].max():9.3f}"
        )
    print(
        f"max over all: parametric {shifts['parametric'].max():.2e} deg, SVR {shifts['SVR'].max():.3f} deg "
        f"(mean {shifts['SVR'].mean():.3f}); box-trained: parametric {shifts['box parametric'].max():.2e}, "
        f"SVR {shifts['box SVR'].max():.3f} deg"
    )


def speed(tp: Transform, ts: Transform, side: int, svr_limit: float) -> None:
    print(f"\n## 3. speed: a {side}^2 alpha map and a {side}^2 x 3 RGB rho_s map")
    rng = np.random.default_rng(0)
    alpha = rng.uniform(0.02, 0.99, (side, side))
    rho = rng.uniform(0.02, 0.3, (side, side, 3))
    x = {"roughness": alpha, "reflectance": rho}
    n_sv = sum(len(m["support_vectors"]) for m in ts.mappings.values() if m["kind"] == "svr")

    def mappings(tr: Transform, xx: dict) -> float:
        t = time.perf_counter()
        for m in tr.mappings.values():
            _evaluate(tr.method, m, xx)
        return time.perf_counter() - t

    def full(tr: Transform, a: np.ndarray, r: np.ndarray) -> float:
        t = time.perf_counter()
        tr.apply({"alpha": a, "specularReflectance": r})
        return time.perf_counter() - t

    # the regression alone on a tile (both methods, like for like), then end to end on the full map;
    # SVR on the full map only if the tile predicts less than svr_limit seconds
    small = min(1024, side)
    scale = (side // small) ** 2
    tile = {k: np.ascontiguousarray(v[:small, :small]) for k, v in x.items()}
    p_map = min(mappings(tp, tile) for _ in range(3))  # best of three: the first run also pays page faults
    s_map = min(mappings(ts, tile) for _ in range(2))
    alpha, rho = alpha.astype(np.float32), rho.astype(np.float32)  # maps as a texture reader gives them
    p_full = min(full(tp, alpha, rho) for _ in range(3))  # best of three, as above
    if s_map * scale <= svr_limit:
        s_full, how = full(ts, alpha, rho), "measured"
    else:
        s_full = full(ts, alpha[:small, :small], rho[:small, :small]) * scale
        how = f"EXTRAPOLATED linearly from a {small}^2 tile (x {scale})"
    print(f"{'seconds':<56} {'parametric':>10} {'SVR':>8} {'ratio':>7}")
    print(
        f"{f'mappings only, {small}^2 tile (float64 quantity maps)':<56} {p_map:10.3f} {s_map:8.3f} "
        f"{s_map / p_map:6.0f}x"
    )
    print(
        f"{f'Transform.apply, {side}^2 (float32 maps, end to end)':<56} {p_full:10.2f} {s_full:8.2f} "
        f"{s_full / p_full:6.0f}x"
    )
    print(f"SVR end to end {how}; {n_sv} support vectors in all ({svs(ts)})")


def authors(size: int, workers: int, cache: Path) -> None:
    print("\n## 4. the authors' grid (35 alpha1 x 23 rho_s)")
    db, seconds, done = sweep(GRID_AUTHORS, size, workers, cache)
    data = load_training_data(db)
    tp = transform_from_data(data, "parametric")
    ra, rf = np.ptp(data.y["roughness"]), np.ptp(data.y["reflectance"])
    ea, ef = tp.mappings["roughness"]["heldout_rmse"], tp.mappings["reflectance"]["heldout_rmse"]
    print(
        f"our sweep ({len(data)} points, {done} swept now in {seconds:.1f} s): held-out RMSE alpha2 {ea:.5f} = "
        f"{100 * ea / ra:.3f}% of range, F0 {ef:.6f} = {100 * ef / rf:.3f}% of range "
        f"(degree {tp.mappings['roughness']['degree']}, k form {tp.mappings['reflectance']['form']})"
    )
    if not TABLE.is_file():
        print(f"authors' table not found at {TABLE}: skipped")
        return
    with TABLE.open() as f:
        rows = [
            {k: float(r[k]) for k in ("alpha1", "specular1", "alpha2", "eta2")}
            for r in csv.DictReader(f, delimiter="\t")
        ]
    a1, s1 = np.array([r["alpha1"] for r in rows]), np.array([r["specular1"] for r in rows])
    a2, f0 = np.array([r["alpha2"] for r in rows]), np.array([r["eta2"] for r in rows])
    mr = parametric.fit_roughness(a1, a2)
    mf = parametric.fit_reflectance(a1, np.repeat(s1[:, None], 3, 1), np.repeat(f0[:, None], 3, 1))
    print(
        f"their table ({len(rows)} rows), parametric forms fitted directly: held-out RMSE alpha2 "
        f"{mr['heldout_rmse']:.5f} = {100 * mr['heldout_rmse'] / np.ptp(a2):.3f}% of range, F0 "
        f"{mf['heldout_rmse']:.6f} = {100 * mf['heldout_rmse'] / np.ptp(f0):.3f}% of range "
        f"(degree {mr['degree']}, k form {mf['form']}, c = {np.round(mf['coef'], 4).tolist()})"
    )
    # our parametric transform (from our sweep) against their table
    pa, pf = predict(tp, a1, s1)
    for label, m in (("all rows", a1 > 0), ("alpha1 >= 0.03", a1 >= 0.03)):
        ea, ef = rmse(pa[m], a2[m]), rmse(pf[m, 0], f0[m])
        print(
            f"our sweep's transform on their table, {label} ({m.sum()}): RMSE alpha2 {ea:.5f} = "
            f"{100 * ea / np.ptp(a2):.3f}%, F0 {ef:.6f} = {100 * ef / np.ptp(f0):.3f}% of range"
        )


def plots(data: TrainingData, inbox: np.ndarray, tp: Transform, ts: Transform, folder: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    folder.mkdir(parents=True, exist_ok=True)
    a, s = data.x["roughness"], data.x["reflectance"][:, 0]
    ya, yf = data.y["roughness"], data.y["reflectance"][:, 0]
    grid_a = np.linspace(a.min(), a.max(), 300)

    # alpha_2 against alpha_1, points coloured by rho_s
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    ax.axvspan(a.min(), BOX_ALPHA, color="0.9", zorder=0, label=f"training box (alpha1 <= {BOX_ALPHA})")
    sc = ax.scatter(a, ya, c=s, s=14, cmap="viridis", edgecolors=np.where(inbox, "k", "none"), linewidths=0.5, zorder=2)
    fig.colorbar(sc, ax=ax, label="rho_s (Ward)")
    ax.plot(grid_a, predict(tp, grid_a, np.full(grid_a.shape, 0.1))[0], "C3", lw=2, label="parametric", zorder=3)
    for rho, style in ((0.1, ":"), (0.25, "--")):
        ax.plot(
            grid_a,
            predict(ts, grid_a, np.full(grid_a.shape, rho))[0],
            "k" + style,
            lw=1.5,
            label=f"SVR (rho_s = {rho})",
            zorder=3,
        )
    ax.set(xlabel="alpha1 (Ward)", ylabel="alpha2 (Mitsuba AS)", title="Ward -> AS roughness: data and regressions")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "alpha2-vs-alpha1.png", dpi=120)
    plt.close(fig)

    # F0 against rho_s for a few alpha_1
    fig, ax = plt.subplots(figsize=(6.4, 4.8))
    levels = np.unique(a)
    picks = levels[np.linspace(0, len(levels) - 1, 5).round().astype(int)]
    grid_s = np.linspace(s.min(), s.max(), 100)
    ax.add_patch(
        Rectangle(
            (s.min(), 0),
            BOX_RHO - s.min(),
            yf.max() * 1.05,
            color="0.9",
            zorder=0,
            label=f"training box (rho_s <= {BOX_RHO}, alpha1 <= {BOX_ALPHA})",
        )
    )
    for i, al in enumerate(picks):
        m = np.isclose(a, al)
        ax.scatter(s[m], yf[m], s=16, color=f"C{i}", zorder=2, label=f"alpha1 = {al:.2f}")
        ax.plot(grid_s, predict(tp, np.full(grid_s.shape, al), grid_s)[1][:, 0], color=f"C{i}", lw=1.5, zorder=3)
        ax.plot(grid_s, predict(ts, np.full(grid_s.shape, al), grid_s)[1][:, 0], color=f"C{i}", lw=1, ls="--", zorder=3)
    ax.plot([], [], "k-", label="parametric k(alpha1) rho_s")
    ax.plot([], [], "k--", label="SVR")
    ax.set(
        xlabel="rho_s (Ward)",
        ylabel="F0 (Mitsuba AS)",
        title="Ward -> AS reflectance: data and regressions",
        ylim=(0, yf.max() * 1.05),
    )
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(folder / "f0-vs-rho.png", dpi=120)
    plt.close(fig)
    print(
        f"\n## 5. plots: {folder / 'alpha2-vs-alpha1.png'}, {folder / 'f0-vs-rho.png'} "
        "(transforms trained on the box only)"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", type=int, default=64, help="probe scene resolution of the sweeps")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--side", type=int, default=4096, help="texture side for the speed test")
    ap.add_argument(
        "--svr-limit",
        type=float,
        default=120.0,
        help="time the full map with SVR only if the estimate is below this many seconds",
    )
    ap.add_argument("--plots", type=Path, default=ROOT / "docs" / "img" / "regression")
    ap.add_argument("--no-plots", action="store_true")
    ap.add_argument("--only", choices=("speed",), help="run only this part (on the cached box sweep)")
    ap.add_argument("--cache", type=Path, default=Path(tempfile.gettempdir()) / "matremap-bench-regression")
    args = ap.parse_args()
    args.cache.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()

    db, seconds, done = sweep(GRID_BOX, args.size, args.workers, args.cache)
    data = load_training_data(db)
    print(
        f"sweep Ward -> AS {GRID_BOX}, resolution {args.size}, {args.workers} workers: {len(data)} points "
        f"({done} swept now in {seconds:.1f} s; cache {db})"
    )
    tp_box, ts_box, inbox = subbox(data)
    tp, t_p = timed_learn(data, "parametric")
    ts, t_s = timed_learn(data, "svr")
    print(f"\nwhole sweep learned in {t_p:.1f} s (parametric) and {t_s:.1f} s (SVR: {svs(ts)})")
    if args.only == "speed":
        speed(tp, ts, args.side, args.svr_limit)
        return
    hue(tp, ts, tp_box, ts_box)
    speed(tp, ts, args.side, args.svr_limit)
    authors(args.size, args.workers, args.cache)
    if not args.no_plots:
        plots(data, inbox, tp_box, ts_box, args.plots)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
