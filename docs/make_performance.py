"""Write the manual's performance page from the benchmark results, at every build.

    python docs/make_performance.py [RESULTS_DIR] [OUT.md]

``docs/conf.py`` calls :func:`write_page` before Sphinx reads the sources, so the page's numbers
are those of ``benchmarks/results/*.json`` in the checkout being built and cannot drift from
them.  Each table names the file (and the key inside it) its numbers come from; a file that is
not there is skipped with a line saying so, and the rest of the page is still written.
Numbers are printed as stored, rounded for reading only.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

#: the files the page reads, in page order, with the function that turns each into Markdown
SOURCES = ("work_precision.json", "long_chain.json", "active_chains.json", "active_paired.json",
           "native_ranks.json", "output_cost.json", "lammps_native.json")


def fmt(value, digits: int = 3) -> str:
    """A number for a table: ``digits`` significant figures, "-" for None."""
    if value is None:
        return "-"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        value = int(value)
    if isinstance(value, int):
        return f"{value:,}".replace(",", " ")
    if abs(value) >= 10**digits:
        return f"{value:,.0f}".replace(",", " ")
    if abs(value) >= 1e-3:
        return f"{value:#.{digits}g}"  # trailing zeros kept: 4.00, not 4
    return f"{value:.{digits}g}"


def table(header: list, rows: list) -> str:
    """A Markdown pipe table."""
    lines = ["| " + " | ".join(header) + " |", "|" + " --- |" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def source_line(name: str, key: str = "") -> str:
    """The line under a table that says where its numbers come from."""
    where = f", key `{key}`" if key else ""
    return f"*Source: `benchmarks/results/{name}`{where}.*"


def work_precision(data: dict, name: str) -> str:
    """Per scene and method: the orders of convergence and the wall time to a ledger error of
    the file's target (``summary`` of each scene)."""
    target = data.get("target_ledger_error")
    parts = [f"Wall time to reach an energy-ledger error of {fmt(target)} E_imp, and the "
             "observed order of convergence of the trajectory and of the ledger in the "
             "method's setting (tolerance or step); *extrapolated* marks a time read off the "
             "fitted line beyond the measured settings."]
    for result in data["results"]:
        rows = []
        for method, s in result["summary"].items():
            rows.append([method, s.get("order_in", "-"), fmt(s.get("order_trajectory")),
                         fmt(s.get("order_ledger")),
                         fmt(s.get(f"wall_s_at_ledger_{target:g}".replace("e-0", "e-"))),
                         fmt(s.get("extrapolated"))])
        parts.append(f"**{result['scene']}** to t = {fmt(result['duration'])}:\n\n" + table(
            ["method", "setting", "order (trajectory)", "order (ledger)",
             f"wall s at {fmt(target)}", "extrapolated"], rows))
    parts.append(source_line(name, "results[].summary"))
    return "\n\n".join(parts)


def long_chain(data: dict, name: str) -> str:
    """A pulse in chains at rest of growing length: wall time and bead-steps actually taken,
    per backend (a row without one is the fast backend's)."""
    rows = [[r.get("backend", "fast"), fmt(r["n"]), fmt(r["velocity"]), fmt(r["duration"]),
             fmt(r["wall_s"]), fmt(r["bead_steps"]), fmt(r["all_bead_steps"]),
             fmt(r["events"])]
            for r in data["rows"] if "error" not in r]
    ratios = [[r.get("backend", "fast"), fmt(r["velocity"]), fmt(r["duration"]), fmt(r["n"]),
               fmt(r["shortest_uncrossed_n"]), fmt(r["ratio_to_shortest_uncrossed"])]
              for r in data["ratios"]]
    return "\n\n".join([
        f"Scene {data.get('scene', '?')}; backend `fast` is the fast backend on one thread, "
        "`native-K` LAMMPS's native contact on K MPI ranks. The beads at rest ahead of the "
        "pulse are not stepped, so *bead-steps taken* stays near what the pulse reaches while "
        "*all* grows with the chain (LAMMPS's own work per step still grows with the chain).",
        table(["backend", "beads", "v0", "t", "wall s", "bead-steps taken", "all bead-steps",
               "events"], rows),
        source_line(name, "rows"),
        "CPU time of the longest chain over that of the shortest chain the pulse never "
        "crosses:",
        table(["backend", "v0", "t", "beads", "shortest uncrossed", "CPU ratio"], ratios),
        source_line(name, "ratios")])


def active_chains(data: dict, name: str) -> str:
    """ns per bead-step, by backend and temperature (0: a quiet chain) against chain length
    ("failed" where the point's run failed: it has no ratio either); the active/moving ratios."""
    ns = sorted({r["n"] for r in data["rows"]})
    cells = {}
    for r in data["rows"]:
        cells[(r["backend"], r["temperature"], r["n"])] = (
            "failed" if "error" in r else fmt(r["ns_per_bead_step_median"]))
    keys = sorted({(r["backend"], r["temperature"]) for r in data["rows"]})
    rows = [[backend, fmt(temp)] + [cells.get((backend, temp, n), "-") for n in ns]
            for backend, temp in keys]
    return "\n\n".join([
        f"Median ns per bead-step (dt = {fmt(data.get('dt'))}, {data.get('cores', '?')} "
        "cores): temperature 0 is a quiet chain, a positive temperature gives every bead a "
        "random initial velocity and so contact events everywhere. Backend `fast-K` is the "
        "fast backend on K threads, `native-K` LAMMPS's native contact on K MPI ranks.",
        table(["backend", "temperature"] + [f"N = {fmt(n)}" for n in ns], rows),
        source_line(name, "rows[].ns_per_bead_step_median"),
        "The active chain (temperature 2) over the chain whose every bead moves (1e-06), "
        "target 1.3 at every N: the median ratio of blocks timed in pairs (both chains in "
        "one process) with its 95 % interval (a row without one: the median of the rounds' "
        "ratios); each round's median beside it.",
        table(["backend", "N", "active / moving", "95 % interval", "rounds"],
              [[r["backend"], fmt(r["n"]), fmt(r["active_over_quiet"]),
                "-" if "ci95" not in r else f"{fmt(r['ci95'][0])}-{fmt(r['ci95'][1])}",
                ", ".join(fmt(x) for x in r["rounds"])]
               for r in data.get("ratios", []) if "active_over_quiet" in r]),
        source_line(name, "ratios[].active_over_quiet")])


def spread_cell(s: dict) -> str:
    """A ratio's median with its 95 % interval (where stored), quartiles and range:
    ``median [ci] (q1-q3; min-max)``."""
    ci = f" [{fmt(s['ci95'][0])}-{fmt(s['ci95'][1])}]" if "ci95" in s else ""
    return (f"{fmt(s['median'])}{ci} ({fmt(s['q1'])}-{fmt(s['q3'])}; "
            f"{fmt(s['min'])}-{fmt(s['max'])})")


def active_paired(data: dict, name: str) -> str:
    """The fast backend's active / moving ratio from blocks timed in pairs, per (N,
    threads)."""
    rows = []
    for r in data["rows"]:
        if "error" in r:
            rows.append([fmt(r["n"]), fmt(r["threads"]), "failed", "-", "-", "-", "-"])
            continue
        rows.append([fmt(r["n"]), fmt(r["threads"]), fmt(r["pairs"]),
                     spread_cell(r["active_over_moving_loop"]),
                     spread_cell(r["active_over_moving_cpu"]),
                     fmt(r["ns_per_bead_step_moving_median"]),
                     fmt(r["ns_per_bead_step_active_median"])])
    temps = data.get("temperatures", {})
    return "\n\n".join([
        "The fast backend's active chain (temperature "
        f"{fmt(temps.get('active'))}) over the same chain with every bead moving "
        f"({fmt(temps.get('moving'))}), both in one process, their blocks of "
        f"{fmt(data.get('steps_per_block'))} steps timed in pairs (a slow spell of the "
        "machine falls on both blocks of a pair): the median ratio of the pairs with its 95 % "
        "interval [in brackets], their quartiles and range, for the compiled loop and for "
        "the CPU time of the whole block (Python's handling of its events included; both "
        "threads on two).",
        table(["beads", "threads", "pairs", "loop ratio", "CPU ratio",
               "ns moving", "ns active"], rows),
        source_line(name, "rows[]")])


def native_ranks(data: dict, name: str) -> str:
    """The native fix's speed-up of two MPI ranks over one from blocks timed in pairs, per
    (N, temperature)."""
    rows = []
    for r in data["rows"]:
        if "error" in r:
            rows.append([fmt(r["n"]), fmt(r["temperature"]), "failed", "-", "-", "-"])
            continue
        s = r["two_over_one_speed"]
        rows.append([fmt(r["n"]), fmt(r["temperature"]), fmt(s["count"]), spread_cell(s),
                     fmt(r["ns_per_bead_step_one_rank_median"]),
                     fmt(r["ns_per_bead_step_two_ranks_median"])])
    return "\n\n".join([
        "LAMMPS's native contact with located events on one MPI rank and on two, the same "
        "chain held twice by one process of two ranks, their blocks of "
        f"{fmt(data.get('block_time'))} time units alternating (a slow spell of the machine "
        "falls on both blocks of a pair): the median of the pairs' speed-ups (one-rank time "
        "over two-rank time) with its 95 % interval [in brackets], their quartiles and range, "
        "and each chain's median ns per bead-step. Temperature 1e-06: every bead moving; 2: "
        "contact events all along the chain. Target 1.8 at 1e6 beads, temperature 2.",
        table(["beads", "temperature", "pairs", "two ranks over one", "ns one rank",
               "ns two ranks"], rows),
        source_line(name, "rows[]")])


#: output_cost.json's cases on the long chain: name -> the output keys it sets
OUTPUT_CASES = {"no_file": "no output file", "full": "(defaults)",
                "full_gzip": "`output.compression = \"gzip\"`",
                "full_lzf": "`output.compression = \"lzf\"`",
                "stride_10": "`output.bead_stride = 10`",
                "stride_10_lzf": "`output.bead_stride = 10`, `output.compression = \"lzf\"`",
                "stride_0": "`output.bead_stride = 0` (observables only)"}


def output_cost(data: dict, name: str) -> str:
    """What writing the output costs, by output setting, on the file's long chain (the cases
    of :data:`OUTPUT_CASES`; other entries of the file are not shown)."""
    rows = []
    for case, keys in OUTPUT_CASES.items():
        r = data["long_chain"].get(case)
        if r is None:
            continue
        size = r.get("file_bytes")
        rows.append([keys, fmt(r.get("wall_s")), fmt(r.get("writer_s")),
                     "-" if size is None else fmt(size / 1e6)])
    load = (data.get("load_before"), data.get("load_after"))
    return "\n\n".join([
        f"A chain of {fmt(data.get('n'))} beads on the fast backend, {fmt(data.get('frames'))} "
        "frames: wall time of the run, time spent in the H5MD writer (the output's own cost, "
        "the least noisy number), and the file's size, per output setting. Fastest of 2 runs "
        f"each; load average {fmt(load[0])} before and {fmt(load[1])} after.",
        table(["output", "wall s", "writer s", "file MB"], rows),
        source_line(name, "long_chain")])


def lammps_native(data: dict, name: str) -> str:
    """LAMMPS's own ``pair_style granular`` against mdgran's laws: the largest force
    difference per law, and the JKR chain's displacement error against the step."""
    laws = [[law, fmt(r.get("max_abs_force_error"))] for law, r in data["force_laws"].items()]
    runs = [[fmt(r["dt"]), fmt(r["duration"]), fmt(r["x_max_abs_error"]),
             fmt(r["v_max_abs_error"])] for r in data["jkr_chain_force_rule"]["runs"]]
    return "\n\n".join([
        f"LAMMPS {data.get('lammps_version', '?')}'s `pair_style granular` against mdgran's "
        "contact laws, force for force (units eta), then a JKR chain (snap-off at the force "
        "maximum, as LAMMPS does) against the reference backend as the step shrinks "
        "(units p and p q):",
        table(["law", "largest force difference"], laws),
        source_line(name, "force_laws"),
        table(["dt", "t", "max displacement error", "max velocity error"], runs),
        source_line(name, "jkr_chain_force_rule.runs")])


TITLES = {
    "work_precision.json": ("Work and precision", work_precision),
    "long_chain.json": ("A pulse in long chains", long_chain),
    "active_chains.json": ("Cost of contact events in long chains", active_chains),
    "active_paired.json": ("Active over moving chain, blocks in pairs", active_paired),
    "native_ranks.json": ("Two MPI ranks over one, blocks in pairs", native_ranks),
    "output_cost.json": ("Cost of the output", output_cost),
    "lammps_native.json": ("LAMMPS's own granular contact", lammps_native),
}


def section(results: Path, name: str) -> str:
    """One section of the page from ``results/name``, or a line saying it is absent."""
    title, render = TITLES[name]
    path = results / name
    if not path.is_file():
        return (f"## {title}\n\n`benchmarks/results/{name}` is not in this checkout: "
                "this table is skipped.")
    return f"## {title}\n\n" + render(json.loads(path.read_text()), name)


def page(results: Path) -> str:
    """The whole page (Markdown)."""
    head = ("# Performance\n\n"
            "The numbers below are read from `benchmarks/results/*.json` when the manual is "
            "built (`docs/make_performance.py`), so they are those of the files in this "
            "checkout; each table says which file and key it comes from. The scripts in "
            "`benchmarks/` write the files, with their spreads and the load of the machine "
            "(a shared 2-core x86-64 machine) at the time. Units are those of the model: "
            "time in 1/q, energy in eta p, lengths in p ([](../physics.md)).")
    return "\n\n".join([head] + [section(results, name) for name in SOURCES]) + "\n"


def write_page(results: Path, out: Path) -> None:
    """Write :func:`page` to ``out`` if it changed (an unchanged page keeps Sphinx's cache)."""
    text = page(Path(results))
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if not out.is_file() or out.read_text() != text:
        out.write_text(text)


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    args = sys.argv[1:]
    results = Path(args[0]) if args else root / "benchmarks" / "results"
    if len(args) > 1:
        write_page(results, Path(args[1]))
    else:
        sys.stdout.write(page(results))
