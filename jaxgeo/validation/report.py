"""The validation report: `run_suite` and `validate` solve the suites' pairs with
every method and the exact polyhedral reference into a `Table` of `Row`s (CSV,
Markdown, `read_csv`); `convergence_summary`, `summary_markdown` and
`plot_convergence` for a study over several resolutions."""

from __future__ import annotations

import csv
import math
import os
import sys
import time
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from .._errors import JaxgeoError
from . import references
from .references import MethodResult, available_methods
from .suites import SUITES, Suite


@dataclass(frozen=True)
class Row:
    """One endpoint pair of a suite, solved by every method.

    Errors are relative to the analytic length L, and signed:
    `error(m)` = (L_m − L)/L (total), `discretisation_error` = (L_exact − L)/L (the
    mesh's own error: the shortest path ON the mesh vs the smooth surface),
    `method_error(m)` = (L_m − L_exact)/L (the solver's error on that mesh). With the
    common denominator L, total = method + discretisation exactly (to rounding).
    """

    suite: str
    resolution: int
    n_faces: int
    mesh_size: float
    pair: str
    kind: str
    v1: int
    v2: int
    analytic: float
    exact: float | None
    results: dict[str, MethodResult] = field(default_factory=dict)

    def error(self, method: str) -> float:
        r = self.results[method]
        return (
            (r.length - self.analytic) / self.analytic
            if r.status == "SUCCESS"
            else math.nan
        )

    def method_error(self, method: str) -> float:
        r = self.results[method]
        if self.exact is None or r.status != "SUCCESS":
            return math.nan
        return (r.length - self.exact) / self.analytic

    @property
    def discretisation_error(self) -> float:
        return (
            math.nan
            if self.exact is None
            else (self.exact - self.analytic) / self.analytic
        )


def _pct(x: float, digits: int = 3) -> str:
    return "—" if x is None or math.isnan(x) else f"{100.0 * x:+.{digits}f} %"


def _num(x: float | None, digits: int = 6) -> str:
    return "—" if x is None or math.isnan(x) else f"{x:.{digits}f}"


@dataclass
class Table:
    """Validation results: one `Row` per (suite, resolution, pair).

    `methods`: the solver methods run; `exact_solver`: the name of the exact
    polyhedral reference (None if none was installed); `compile_time[(suite,
    resolution, method)]`: seconds of the first call (JIT compilation included).
    """

    rows: list[Row]
    methods: tuple[str, ...]
    exact_solver: str | None
    compile_time: dict[tuple[str, int, str], float] = field(default_factory=dict)

    def columns(self) -> dict[str, list]:
        """The table as a dict of equal-length columns (raw numbers, errors as
        relative fractions, NaN where not available)."""
        cols: dict[str, list] = {
            k: []
            for k in (
                "suite",
                "resolution",
                "n_faces",
                "mesh_size",
                "pair",
                "kind",
                "v1",
                "v2",
                "analytic",
                "exact",
                "exact_solver",
                "discretisation_error",
            )
        }
        for m in self.methods:
            for k in ("length", "status", "error", "method_error", "time"):
                cols[f"{m}_{k}"] = []
        for r in self.rows:
            for k in ("suite", "resolution", "n_faces", "mesh_size", "pair", "kind"):
                cols[k].append(getattr(r, k))
            cols["v1"].append(r.v1)
            cols["v2"].append(r.v2)
            cols["analytic"].append(r.analytic)
            cols["exact"].append(math.nan if r.exact is None else r.exact)
            cols["exact_solver"].append(
                self.exact_solver if r.exact is not None else ""
            )
            cols["discretisation_error"].append(r.discretisation_error)
            for m in self.methods:
                res = r.results[m]
                cols[f"{m}_length"].append(res.length)
                cols[f"{m}_status"].append(res.status)
                cols[f"{m}_error"].append(r.error(m))
                cols[f"{m}_method_error"].append(r.method_error(m))
                cols[f"{m}_time"].append(res.time)
        return cols

    def to_csv(self, file: str | os.PathLike | typing.TextIO) -> None:
        """Write `columns()` as CSV (full precision)."""
        cols = self.columns()
        if not hasattr(file, "write"):
            # (hasattr(file, 'write') told a path from a text file)
            with open(file, "w", newline="") as f:  # pyright: ignore[reportCallIssue, reportArgumentType]
                return self.to_csv(f)
        w = csv.writer(file)  # pyright: ignore[reportArgumentType]
        w.writerow(cols)
        for row in zip(*cols.values()):
            w.writerow([repr(x) if isinstance(x, float) else x for x in row])
        return None

    def to_markdown(self) -> str:
        """The table in Markdown, errors in per cent, one section per suite and
        resolution."""
        exact_name = self.exact_solver or "not installed"
        head = [
            "pair",
            "kind",
            "analytic",
            f"exact polyhedral ({exact_name})",
            "discr. err",
        ]
        for m in self.methods:
            head += [m, f"{m} err", f"{m} method err", f"{m} ms"]
        out = []
        for (suite, res), rows in _groups(self.rows).items():
            r0 = rows[0]
            out.append(
                f"**{suite}**, resolution {res}: {r0.n_faces} faces, mean edge "
                f"length {r0.mesh_size:.4f}\n"
            )
            out.append("| " + " | ".join(head) + " |")
            out.append("|" + "|".join(["---"] * 2 + ["---:"] * (len(head) - 2)) + "|")
            for r in rows:
                cells = [r.pair, r.kind, _num(r.analytic), _num(r.exact)]
                cells.append(_pct(r.discretisation_error))
                for m in self.methods:
                    res = r.results[m]
                    length = _num(res.length)
                    if res.status != "SUCCESS":
                        length += f" ({res.status})"
                    cells += [
                        length,
                        _pct(r.error(m)),
                        _pct(r.method_error(m)),
                        f"{1e3 * res.time:.0f}",
                    ]
                out.append("| " + " | ".join(cells) + " |")
            out.append("")
        return "\n".join(out)


def read_csv(file: str | os.PathLike) -> Table:
    """A `Table` from a file written by `Table.to_csv` (`compile_time` is not
    stored, so it comes back empty)."""
    with open(file, newline="") as f:
        records = list(csv.DictReader(f))
    if not records:
        raise JaxgeoError(f"{file}: no rows")
    methods = tuple(k[: -len("_status")] for k in records[0] if k.endswith("_status"))

    def num(x: str) -> float:
        return float(x) if x else math.nan

    rows = []
    for rec in records:
        exact = num(rec["exact"])
        rows.append(
            Row(
                rec["suite"],
                int(rec["resolution"]),
                int(rec["n_faces"]),
                num(rec["mesh_size"]),
                rec["pair"],
                rec["kind"],
                int(rec["v1"]),
                int(rec["v2"]),
                num(rec["analytic"]),
                None if math.isnan(exact) else exact,
                {
                    m: MethodResult(
                        num(rec[f"{m}_length"]),
                        rec[f"{m}_status"],
                        num(rec[f"{m}_time"]),
                    )
                    for m in methods
                },
            )
        )
    names = {rec.get("exact_solver") or "" for rec in records} - {""}
    if not any(r.exact is not None for r in rows):
        return Table(rows, methods, None)
    return Table(rows, methods, names.pop() if len(names) == 1 else "from file")


def _groups(rows: list[Row]) -> dict[tuple[str, int], list[Row]]:
    groups: dict[tuple[str, int], list[Row]] = {}
    for r in rows:
        groups.setdefault((r.suite, r.resolution), []).append(r)
    return groups


def run_suite(
    suite: Suite,
    methods: Sequence[str] | None = None,
    exact_solver: str = "auto",
    progress: Callable[[str], None] | None = None,
    **solver_options: typing.Any,
) -> Table:
    """Solve every pair of `suite` with every method and the exact polyhedral solver.

    **Arguments:** `methods`: `jaxgeo.shortest_path` methods (default
    `available_methods()`); `exact_solver`: see `references.exact_solver`;
    `progress`: called with one line of text per step; `solver_options`: passed to
    `shortest_path`.

    **Returns:** a `Table`. Endpoints are mesh vertices (passed as 3-D points), so
    the analytic length is exact for them. Each method is called once on the first
    pair before timing, so `MethodResult.time` excludes JIT compilation (reported
    in `Table.compile_time`). Failed traces are recorded with their status, not
    raised.
    """
    from ..geodesic import shortest_path
    from ..mesh import Mesh
    from ..path import Status

    methods = tuple(available_methods() if methods is None else methods)
    say = progress or (lambda _: None)
    tag = f"[{suite.name} r{suite.resolution}]"
    mesh = Mesh(suite.vertices, suite.faces)
    mesh_size = float(mesh.mean_edge_length)
    name, exact = references.exact_solver(exact_solver, suite.vertices, suite.faces)
    rows = []
    t0 = time.perf_counter()
    for p in suite.pairs:
        d = exact(p.v1, p.v2) if exact else None
        rows.append(
            Row(
                suite.name,
                suite.resolution,
                mesh.n_faces,
                mesh_size,
                p.pair,
                p.kind,
                p.v1,
                p.v2,
                p.analytic,
                d,
            )
        )
    if exact:
        say(f"{tag} exact polyhedral ({name}): {time.perf_counter() - t0:.1f} s")
    table = Table(rows, methods, name)
    v = np.asarray(suite.vertices)
    for m in methods:
        say(f"{tag} {m}: compiling ({mesh.n_faces} faces)")
        t0 = time.perf_counter()
        first = suite.pairs[0]
        # (m: a method's name as given; shortest_path rejects an unknown one)
        path = shortest_path(
            mesh,
            v[first.v1],
            v[first.v2],
            method=m,  # pyright: ignore[reportArgumentType]
            throw=False,
            **solver_options,
        )
        float(path.length)
        table.compile_time[(suite.name, suite.resolution, m)] = time.perf_counter() - t0
        for k, (p, row) in enumerate(zip(suite.pairs, rows)):
            t0 = time.perf_counter()
            path = shortest_path(
                mesh,
                v[p.v1],
                v[p.v2],
                method=m,  # pyright: ignore[reportArgumentType]
                throw=False,
                **solver_options,
            )
            length = float(path.length)
            dt = time.perf_counter() - t0
            status = Status(int(path.status)).name
            row.results[m] = MethodResult(length, status, dt)
            say(
                f"{tag} {m} {k + 1}/{len(suite.pairs)} {p.pair}: {length:.6f} "
                f"({_pct(row.error(m))}, {status.lower()}, {dt:.2f} s)"
            )
    return table


def _merge(tables: list[Table]) -> Table:
    out = Table([], tables[0].methods, tables[0].exact_solver)
    for t in tables:
        out.rows += t.rows
        out.compile_time.update(t.compile_time)
    return out


def validate(
    resolutions: int | Sequence[int] = 4,
    suites: Sequence[str] = ("sphere", "catenoid"),
    methods: Sequence[str] | None = None,
    exact_solver: str = "auto",
    progress: Callable[[str], None] | None = None,
    **solver_options: typing.Any,
) -> Table:
    """Run the named suites (`SUITES`) at one or several resolutions; see
    `run_suite`. Several resolutions make a convergence study
    (`convergence_summary`, `plot_convergence`)."""
    import jax

    if isinstance(resolutions, int):
        resolutions = [resolutions]
    for name in suites:
        if name not in SUITES:
            raise JaxgeoError(f"unknown suite {name!r}; expected one of {list(SUITES)}")
    tables = []
    for res in resolutions:
        for name in suites:
            tables.append(
                run_suite(
                    SUITES[name](res), methods, exact_solver, progress, **solver_options
                )
            )
            # Every suite and resolution compiles programs of its own mesh size,
            # which the next does not reuse, and XLA's CPU executables keep their
            # code mapped: `--resolution 3,4,5` reached ~60k memory maps, near
            # Linux's default limit of 65,530 (vm.max_map_count), past which LLVM
            # fails with "Cannot allocate memory". Dropping the compiled programs
            # unmaps them (icosphere(3) and (4) laser: 2,126 -> 1,020 maps).
            jax.clear_caches()
    return _merge(tables)


def convergence_summary(table: Table) -> list[dict[str, typing.Any]]:
    """Per (suite, resolution): `n_faces`, `mesh_size` and the median absolute
    relative errors: `exact` (discretisation error of the exact polyhedral
    geodesic), and per method `m` (total error) and `m_method` (vs exact)."""
    out = []
    for (suite, res), rows in _groups(table.rows).items():
        entry: dict[str, typing.Any] = {
            "suite": suite,
            "resolution": res,
            "n_faces": rows[0].n_faces,
            "mesh_size": rows[0].mesh_size,
            "exact": _median_abs([r.discretisation_error for r in rows]),
        }
        for m in table.methods:
            entry[m] = _median_abs([r.error(m) for r in rows])
            entry[f"{m}_method"] = _median_abs([r.method_error(m) for r in rows])
        out.append(entry)
    return out


def _median_abs(xs: list[float]) -> float:
    a = np.abs(np.asarray(xs, dtype=np.float64))
    a = a[np.isfinite(a)]
    return float(np.median(a)) if a.size else math.nan


def summary_markdown(
    summary: list[dict[str, typing.Any]], methods: Sequence[str]
) -> str:
    """`convergence_summary` as a Markdown table (median |error| in per cent)."""
    head = ["suite", "resolution", "faces", "mean edge", "exact polyhedral"]
    head += [f"{m} {k}" for m in methods for k in ("total", "method")]
    lines = [
        "| " + " | ".join(head) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(head) - 1)) + "|",
    ]
    for e in summary:
        cells = [
            e["suite"],
            str(e["resolution"]),
            str(e["n_faces"]),
            f"{e['mesh_size']:.4f}",
        ]
        cells.append(_pct(e["exact"]).lstrip("+"))
        for m in methods:
            cells += [_pct(e[m]).lstrip("+"), _pct(e[f"{m}_method"]).lstrip("+")]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _loglog(ax, entries: list[dict[str, typing.Any]], key: str, **kw) -> None:
    h = np.array([e["mesh_size"] for e in entries])
    y = np.array([e[key] for e in entries], dtype=float)
    ok = np.isfinite(y) & (y > 0)
    if ok.any():
        ax.loglog(h[ok], y[ok], marker="o", **kw)


def plot_convergence(
    summary: list[dict[str, typing.Any]],
    methods: Sequence[str],
    file=None,
    axes=None,
):
    """Log–log plot of the median |relative error| against the mean edge length,
    one panel per suite: each method's total error (solid), its method error
    (dashed) and the exact polyhedral reference (black). With `file`, saves a PNG
    (Agg backend when pyplot is not yet in use). Returns the figure."""
    import matplotlib

    if axes is None and "matplotlib.pyplot" not in sys.modules:
        matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    suites = list(dict.fromkeys(e["suite"] for e in summary))
    if axes is None:
        fig, axes = plt.subplots(
            1, len(suites), figsize=(5.5 * len(suites), 4.2), squeeze=False
        )
        axes = axes[0]
    else:
        fig = axes[0].figure
    for ax, suite in zip(axes, suites):
        es = sorted(
            (e for e in summary if e["suite"] == suite), key=lambda e: e["mesh_size"]
        )
        h = np.array([e["mesh_size"] for e in es])

        _loglog(ax, es, "exact", color="k", label="exact polyhedral vs analytic")
        for k, m in enumerate(methods):
            color = f"C{k}"
            _loglog(ax, es, m, color=color, label=f"{m} vs analytic")
            _loglog(
                ax,
                es,
                f"{m}_method",
                color=color,
                ls="--",
                label=f"{m} vs exact polyhedral",
            )
        if len(h) > 1:
            ref = np.array([e["exact"] for e in es], dtype=float)
            if np.isfinite(ref[-1]) and ref[-1] > 0:
                ax.loglog(
                    h, ref[-1] * (h / h[-1]) ** 2, color="0.7", lw=0.8, label="O(h²)"
                )
        ax.set_title(suite)
        ax.set_xlabel("mean edge length h")
        ax.set_ylabel("median |relative length error|")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    if file is not None:
        fig.savefig(file, dpi=120)
    return fig
