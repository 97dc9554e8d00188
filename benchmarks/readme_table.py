"""Write the performance table of docs/performance.md from benchmarks/results.json (`make bench`).

Usage: ``python benchmarks/readme_table.py [results.json] [--print]``: rewrites the table between
the two marker lines of ``docs/performance.md`` (``--print`` prints it instead). Every number in
the table is read from the file; each row names the section it comes from, its date and the
1-minute load average before and after that section ran (the machine's core count heads the
table). A section the file lacks is left out.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results.json"
DOC = Path(__file__).resolve().parents[1] / "docs" / "performance.md"
BEGIN = "<!-- benchmarks/readme_table.py: begin -->"
END = "<!-- benchmarks/readme_table.py: end -->"


def cpu_total(by_rule: dict) -> float:
    """CPU seconds summed over every rule's jobs."""
    return sum(row["cpu_s"] for row in by_rule.values())


def when(section: dict) -> str:
    """``date, load a → b`` of a results.json section."""
    before, after = section.get("load_1min_before"), section.get("load_1min_after")
    load = f", load {before:.1f} → {after:.1f}" if before is not None else ""
    return f"{section['date']}{load}"


def versus_r(r: dict, cores: int) -> str:
    """``(R 112.7 s: 4.5× faster)`` for a cold run, if results.json has the ratio."""
    ratio = r.get(f"vs_r_cores{cores}")
    if ratio is None:
        return ""
    speed = f"{ratio:.1f}× faster" if ratio >= 1 else f"{1 / ratio:.1f}× slower"
    return f" (R {r['r_reference_s']:.1f} s: {speed})"


def cpu_split(r: dict) -> str:
    """``T CPU s (jobs J, Snakemake S)``: every process of a cold run, or the jobs' sum."""
    jobs = cpu_total(r["by_rule"])
    if "cold_cores2_cpu_s" not in r:
        return f"{jobs:.1f} CPU s (jobs)"
    snakemake = r["cold_cores2_cpu_s"] - jobs
    if r.get("served_jobs"):
        server = r["job_server_cpu_s"]
        return (
            f"{r['cold_cores2_cpu_s']:.1f} CPU s (jobs {jobs:.1f}, {r['served_jobs']} of them "
            f"forked from the job server; its preload {server:.1f}; Snakemake and the jobs' "
            f"shells {snakemake - server:.1f})"
        )
    return f"{r['cold_cores2_cpu_s']:.1f} CPU s (jobs {jobs:.1f}, Snakemake {snakemake:.1f})"


def dag_rows(dag: dict) -> list[tuple[str, str, str]]:
    r = dag["results"]
    rows = [
        (
            "paper DAG (fig01–fig11) cold, `--cores 2`",
            f"{r['cold_cores2_s']:.1f} s{versus_r(r, 2)}",
            "≤ 25 s",
        ),
        ("same, `--cores 1`", f"{r['cold_cores1_s']:.1f} s{versus_r(r, 1)}", "≤ 45 s"),
        ("same (`--cores 2`), CPU s of every process", cpu_split(r), "–"),
        ("no-op rerun", f"{r['noop_rerun_s']:.2f} s", "≤ 1.5 s"),
    ]
    if "noop_dry_run_s" in r:
        dry = f"{r['noop_dry_run_s']:.2f} s ({r['noop_dry_run_cpu_s']:.2f} CPU s)"
        rows.append(("no-op dry run `snakemake -n`", dry, "≤ 1.5 s"))
    return rows


def figures_rows(figures: dict) -> list[tuple[str, str, str]]:
    r = figures["results"]
    return [
        (
            "`make figures` cold (every artifact), `--cores 2`",
            f"{r['cold_cores2_s']:.1f} s",
            "≤ 120 s",
        ),
        ("same, CPU s of every process", cpu_split(r), "–"),
    ]


def job_table(dag: dict) -> str:
    """Per rule of the paper DAG's cold `--cores 2` run: jobs and CPU s, largest first."""
    r = dag["results"]
    total = cpu_total(r["by_rule"])
    source = "the processes (`os.wait4`)" if "jobs" in r else "the rules' `benchmark:` files"
    lines = [
        f"CPU seconds per rule of the paper DAG, cold `--cores 2` (`dag`, {when(dag)}; from "
        f"{source}):",
        "",
        "| rule | jobs | CPU s | share |",
        "|---|---|---|---|",
    ]
    for rule, row in r["by_rule"].items():
        share = 100 * row["cpu_s"] / total if total else 0.0
        lines.append(f"| `{rule}` | {row['jobs']} | {row['cpu_s']:.1f} | {share:.0f} % |")
    return "\n".join(lines)


def em_memory(em: dict) -> str:
    """The EM iteration's peak RSS and what it holds: imports, X, the iteration's arrays."""
    text = f"{em['peak_mb']:.0f} MB (after imports {em['baseline_mb']:.0f}"
    if em.get("rss_file_mb") is not None:
        text += f"; {em['rss_file_mb']:.0f} mapped from library files"
    return text + f"; one iteration's arrays {em['iteration_peak_mb']:.0f} by tracemalloc)"


def hmm_rows(hmm: dict) -> list[tuple[str, str, str]]:
    rows = {(r["engine"], r["T"]): r for r in hmm["results"]}
    out = []
    em = rows.get(("em-dtwin", 1_000_000))
    if em:
        stock = rows.get(("em-hmmlearn", 1_000_000))
        beside = f"; hmmlearn {stock['seconds_per_iteration']:.2f} s" if stock else ""
        out.append(
            (
                "one EM iteration at T = 1e6 (K 4, D 10), wall",
                f"{em['seconds_per_iteration']:.2f} s "
                f"({em['cpu_seconds_per_iteration']:.2f} CPU s{beside})",
                "≤ 0.3 s",
            )
        )
        out.append(("same, peak RSS of the process", em_memory(em), "≤ 300 MB"))
    fit, stock_fit = rows.get(("dtwin", 1_000_000)), rows.get(("hmmlearn", 1_000_000))
    if fit:
        beside = f" (hmmlearn {stock_fit['peak_mb']:.0f} MB)" if stock_fit else ""
        out.append(
            ("whole 10-start fit at T = 1e6, peak RSS", f"{fit['peak_mb']:.0f} MB{beside}", "–")
        )
    fits = [t for t in (10_000, 100_000, 1_000_000) if ("dtwin", t) in rows]
    if fits:
        ours = " / ".join(f"{rows[('dtwin', t)]['seconds_per_iteration']:.3f}" for t in fits)
        theirs = " / ".join(
            f"{rows[('hmmlearn', t)]['seconds_per_iteration']:.3f}"
            for t in fits
            if ("hmmlearn", t) in rows
        )
        label = " / ".join(f"1e{len(str(t)) - 1}" for t in fits)
        out.append(
            (
                f"whole 10-start fit, s per EM iteration at T = {label}",
                f"{ours} (hmmlearn {theirs})",
                "–",
            )
        )
    return out


def gap_rows(gap: dict) -> list[tuple[str, str, str]]:
    r = gap["results"]
    seconds = f"{r['diagnose_2000_samples_s']:.1f} / {r['diagnose_100000_samples_s']:.1f} s"
    return [("`dtwin diagnose`, 2,000 / 100,000 samples (CLI)", seconds, "–")]


def monitor_rows(monitor: dict) -> list[tuple[str, str, str]]:
    r = monitor["results"]
    regimes = f"{r['regimes_s']:.0f} s ({r['regimes_cpu_s']:.0f} CPU s; K = {r['k_chosen']})"
    lines = (
        f"{r['samples_per_s']:,} samples/s (one line per sample; "
        f"{r['samples_per_s_every_100']:,} with `--every 100`)"
    )
    latency = (
        f"{r['latency_ms_median']:.2f} ms median, {r['latency_ms_p99']:.2f} ms 99th percentile"
    )
    if "latency_cpu_ms_mean" in r:
        latency += f" ({r['latency_cpu_ms_mean']:.2f} CPU ms a line)"
    return [
        ("`dtwin regimes`, 100,000 samples, paper-size twin, K by BIC (CLI)", regimes, "≤ 60 s"),
        ("`dtwin monitor`, K = 8, 5 channels, one core", lines, "≥ 50,000 samples/s"),
        ("same, a live stream: one line at a time", latency, "≤ 1 ms"),
    ]


def imports_rows(imports: dict) -> list[tuple[str, str, str]]:
    cpu = sorted(row["cpu_s"] for row in imports["results"].values())
    median = cpu[len(cpu) // 2]
    return [
        (
            f"a script's imports, CPU s (median / max of {len(cpu)})",
            f"{median:.2f} / {cpu[-1]:.2f}",
            "–",
        )
    ]


def tests_rows(tests: dict) -> list[tuple[str, str, str]]:
    r = tests["results"]
    cpu = f"{r['test_fast_cpu_s']:.1f} CPU s of every process, {r['test_fast_passed']} passed"
    measured = f"{r['test_fast_s']:.1f} s ({cpu})"
    return [("`make test-fast` (lint, then the tests not marked slow)", measured, "≤ 60 s")]


ROWS = {
    "dag": dag_rows,
    "figures": figures_rows,
    "hmm": hmm_rows,
    "gap": gap_rows,
    "monitor": monitor_rows,
    "imports": imports_rows,
    "tests": tests_rows,
}


def table(results: dict) -> str:
    """The markdown table of ``results`` (the parsed results.json)."""
    machine = results.get("machine", {})
    lines = [
        f"| what ({machine.get('cpus', '?')} cores) | measured | section, date, load | target |",
        "|---|---|---|---|",
    ]
    for name, rows in ROWS.items():
        if name in results:
            for what, value, target in rows(results[name]):
                lines.append(f"| {what} | {value} | `{name}`, {when(results[name])} | {target} |")
    return "\n".join(lines)


def with_table(doc: str, results: dict) -> str:
    """``doc`` (the text of docs/performance.md) with the table between its markers replaced."""
    head, begin, rest = doc.partition(BEGIN)
    _, end, tail = rest.partition(END)
    if not begin or not end:
        raise ValueError(f"{DOC.name} lacks the marker lines {BEGIN!r} and {END!r}")
    return f"{head}{BEGIN}\n{generated(results)}\n{END}{tail}"


def generated(results: dict) -> str:
    """What stands between the markers: the table, then the paper DAG's CPU per rule."""
    parts = [table(results)]
    if "dag" in results:
        parts.append(job_table(results["dag"]))
    return "\n\n".join(parts)


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if a != "--print"]
    results = json.loads((Path(args[0]) if args else RESULTS).read_text())
    if "--print" in sys.argv:
        print(generated(results))
    else:
        DOC.write_text(with_table(DOC.read_text(), results))
