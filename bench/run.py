#!/usr/bin/python3
"""Run the benchmark suite and publish its figures.

Runs <build>/bench/chimera-bench (it builds nothing: `make bench` builds
first), shows its table as it goes, and writes

  bench/results.json    the measured rows, as chimera-bench wrote them
  bench/experiments.json  the experiments' data (MUF overload ramp, scaling)
  docs/benchmarks.md    machine header, the table, the rows not measured yet
  docs/bench/*.png      lateness histogram, ratio and peer bar charts, the MUF
                        overload experiment, scaling against the task count

Run with Debian's /usr/bin/python3: the plots need python3-matplotlib
(`make deps-bench`); without it the figures and Markdown are still written.
"""
import argparse
import datetime
import json
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def sh(*cmd):
    """Output of a command, or '' when it is missing or fails."""
    try:
        return subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                              text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


# The commit measured, read before the run writes its results into the
# tree; "-dirty" only when something other than a previous run's output
# (results, report, plots) differs from it.
def measured_commit():
    head = sh("git", "-C", str(ROOT), "describe", "--always")
    changed = sh("git", "-C", str(ROOT), "status", "--porcelain", "--untracked-files=no", "--", ".",
                 ":!bench/results.json", ":!bench/experiments.json", ":!docs/benchmarks.md", ":!docs/bench")
    return head + ("-dirty" if changed.strip() else "")


COMMIT = measured_commit()


def machine():
    cpuinfo = Path("/proc/cpuinfo").read_text(errors="replace")
    model = next((l.split(":", 1)[1].strip() for l in cpuinfo.splitlines()
                  if l.startswith("model name")), platform.machine())
    flags = next((l for l in cpuinfo.splitlines() if l.startswith("flags")), "")
    vm = sh("systemd-detect-virt", "--vm")
    container = sh("systemd-detect-virt", "--container")
    hyper = "hypervisor" in flags.split()
    if vm and vm != "none":
        virt = f"yes: virtual machine ({vm})"
    elif hyper:
        virt = "yes: virtual machine (hypervisor flag in /proc/cpuinfo)"
    else:
        virt = "no (no hypervisor detected)"
    if container and container != "none":
        virt += f", inside a {container} container"
    try:
        clocksource = Path("/sys/devices/system/clocksource/clocksource0/current_clocksource").read_text().strip()
    except OSError:
        clocksource = "unknown"
    return {
        "cpu": model,
        "clocksource": clocksource,
        "cores": f"{os.cpu_count()} online, {len(os.sched_getaffinity(0))} usable by the suite",
        "kernel": f"{platform.system()} {platform.release()} {platform.version()}",
        "virtualised": virt,
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "commit": COMMIT,
    }


def cpu_times():
    """Per-CPU jiffies from /proc/stat: {"cpu0": (busy+idle total, steal), ...}."""
    out = {}
    try:
        for line in Path("/proc/stat").read_text().splitlines():
            f = line.split()
            if f and f[0].startswith("cpu") and f[0] != "cpu":
                vals = [int(x) for x in f[1:]]
                steal = vals[7] if len(vals) > 7 else 0
                out[f[0]] = (sum(vals[:8]), steal)
    except (OSError, ValueError):
        pass
    return out


def host_share(before, after, load):
    """What the host did beside the run: the hypervisor's steal per CPU (time
    this VM wanted a CPU and another guest had it) and the load average at
    the start (other work in this machine)."""
    parts = []
    for cpu in sorted(after, key=lambda c: int(c[3:])):
        if cpu not in before:
            continue
        total = after[cpu][0] - before[cpu][0]
        steal = after[cpu][1] - before[cpu][1]
        if total > 0:
            parts.append(f"{cpu} {100.0 * steal / total:.1f} %")
    steal = "steal " + ", ".join(parts) if parts else "steal not readable"
    return f"{steal} of the run's time (the hypervisor running others); load average at the start {load}"


def human(v, unit, short=False):
    if v is None:
        return "–"
    if short and unit == "ns":  # the paper's round figures: "220 µs", not "220.00 µs"
        return f"{v:g} ns" if abs(v) < 1000 else f"{v / 1e3:g} µs"
    if unit == "ns":
        a = abs(v)
        if a < 10:
            return f"{v:.2f} ns"
        if a < 1000:
            return f"{v:.1f} ns"
        if a < 1e6:
            return f"{v / 1e3:.2f} µs"
        return f"{v / 1e6:.2f} ms"
    if unit == "%":
        return f"{v:.2f} %"
    return f"{v:.3g}{unit}"


def cell(text):
    """Text safe inside a Markdown table cell."""
    return str(text).replace("|", "\\|")


def markdown(rows, rest, info, commands, quick, elapsed):
    out = ["# Benchmarks", "",
           "Generated by `bench/run.py` from one run of `chimera-bench`; every ratio is "
           "against a peer measured in the same run on the same machine "
           "(absolute times on virtualised machines of this kind are not stable — a system call costs about 1 µs and a cross-core wake-up 50–75 µs, while user-space work runs at native speed — so a figure travels only as a ratio). "
           "Values are medians over repeated runs, with the min–max over those runs; "
           "RT/2 is half a round trip. Each row states its pinning and method. "
           "The paper column is the Chimera II paper's Table 1 (25 MHz 68030, 1991), "
           "for orientation; no ratio is taken against it.", ""]
    out.extend(summary_markdown(rows, rest))
    out.extend(worst_case_markdown(rows))
    out.extend(["## Machine", "",
                f"* CPU: {info['cpu']}",
                f"* cores: {info['cores']}",
                f"* kernel: {info['kernel']}",
                f"* virtualised: {info['virtualised']}",
                f"* Linux clocksource: {info.get('clocksource', 'not recorded')}",
                f"* date: {info['date']}, commit `{info['commit']}`",
                f"* mode: {'quick (few short runs: rough figures)' if quick else 'full'}; "
                f"the run took {elapsed:.0f} s",
                f"* host during the run: {info.get('host', 'not recorded')}",
                f"* command: `{commands[0]}`",
                f"* which ran: `{commands[1]}`", ""])
    chimera = [r for r in rows if not r["name"].startswith("peer_")]
    peers = [r for r in rows if r["name"].startswith("peer_")]

    def table(title, rs, with_peer):
        if not rs:
            return
        out.extend([f"## {title}", ""])
        if with_peer:
            out.append("| row | value | min – max | peer | peer value | ratio | target | "
                       "paper (1991) | config |")
            out.append("| --- | ---: | ---: | --- | ---: | ---: | --- | ---: | --- |")
        else:
            out.append("| row | value | min – max | what | config |")
            out.append("| --- | ---: | ---: | --- | --- |")
        for r in rs:
            u = r["unit"]
            rng = "" if r["min"] is None else f"{human(r['min'], u)} – {human(r['max'], u)}"
            if with_peer:
                met = {True: " ✓", False: " ✗", None: ""}[r.get("target_met")]
                ratio = "" if r["ratio"] is None else f"{r['ratio']:.3g}"
                out.append(f"| `{r['name']}` | {human(r['value'], u)} | {rng} | "
                           f"{'`' + r['peer'] + '`' if r['peer'] else ''} | "
                           f"{human(r['peer_value'], u)} | {ratio} | "
                           f"{(r.get('target') or '') + met} | {human(r['paper_value'], u, short=True)} | "
                           f"{cell(r['config'])} |")
            else:
                out.append(f"| `{r['name']}` | {human(r['value'], u)} | {rng} | "
                           f"{cell(r.get('what', ''))} | {cell(r['config'])} |")
        out.append("")

    table("Chimera", chimera, True)
    table("Peers", peers, False)
    pending = [u for u in rest if u["status"] == "not yet measured"]
    other = [u for u in rest if u["status"] != "not yet measured"]
    if pending:
        out.extend(["## Not yet measured", "",
                    "Catalogue rows (the Chimera II Table 1, the performance targets, the "
                    "predictability rows) whose subsystem is not built yet. They get a figure "
                    "when a measurement for them is added to `bench/` — never before.", "",
                    "| row | what | peer | target | paper (1991) |",
                    "| --- | --- | --- | --- | ---: |"])
        for u in pending:
            out.append(f"| `{u['name']}` | {cell(u['what'])} | "
                       f"{'`' + u['peer'] + '`' if u['peer'] else ''} | {u.get('target') or ''} | "
                       f"{human(u['paper_value'], u['unit'], short=True)} |")
        out.append("")
    if other:
        out.extend(["## Skipped or failed in this run", ""])
        out.extend(f"* `{u['name']}`: {cell(u['status'])}" for u in other)
        out.append("")
    return out


def round_figures(r):
    """The figure each round judged: the ratio for a ratio target, else the value."""
    key = "ratio" if (r.get("target") or "").startswith("ratio") else "value"
    return [x[key] for x in r.get("rounds") or [] if x.get(key) is not None]


def spread(r):
    """'1.10–1.30×' (ratio) or '1.1–1.3 %' (value) over the rounds, or ''."""
    f = round_figures(r)
    if len(f) < 2:
        return ""
    if (r.get("target") or "").startswith("ratio"):
        return f"{min(f):.3g}× to {max(f):.3g}×"
    return f"{human(min(f), r['unit'])} to {human(max(f), r['unit'])}"


def ratio_bound(target):
    """b of a 'ratio <= b' target, else None."""
    t = (target or "").replace(" ", "")
    if not t.startswith("ratio<="):
        return None
    try:
        return float(t[len("ratio<="):])
    except ValueError:
        return None


def floor_beyond(r, by_name):
    """For a ratio target row X that missed: when the run also judges X against
    an in-run floor (row X_vs_floor, whose peer F is itself measured against X's
    peer), and F's own ratio to that peer is above X's bound in every round, no
    design built on that floor can meet X's target on this host. Returns
    (F, its lowest and highest round ratio), else None."""
    bound = ratio_bound(r.get("target"))
    vs = by_name.get(r["name"] + "_vs_floor")
    fl = by_name.get(vs.get("peer")) if vs else None
    if bound is None or r.get("target_met") or not fl or fl.get("peer") != r.get("peer"):
        return None
    f = [x["ratio"] for x in fl.get("rounds") or [] if x.get("ratio") is not None]
    if not f and fl.get("ratio") is not None:
        f = [fl["ratio"]]
    if not f or min(f) <= bound:
        return None
    return fl["name"], min(f), max(f)


def summary_markdown(rows, rest):
    """The one-screen summary: every target, its figure and spread, met or not."""
    targets = [r for r in rows if r.get("target")]
    unjudged = [u for u in rest if u.get("target")]
    met = [r for r in targets if r.get("target_met")]
    by_name = {r["name"]: r for r in rows}
    beyond = {r["name"]: floor_beyond(r, by_name) for r in targets}
    beyond = {k: v for k, v in beyond.items() if v}
    n_rounds = max((r.get("rounds_wanted") or 1 for r in targets), default=1)
    beyond_text = (f" {len(beyond)} of those not met lie{'s' if len(beyond) == 1 else ''} beyond the "
                   "in-run floor the row is built on (the floor's own ratio to the same peer misses "
                   "the target in every round); each is judged against its floor in its `_vs_floor` "
                   "row, which counts as a target of its own." if beyond else "")
    out = ["## Summary", "",
           f"**{len(met)} of {len(targets) + len(unjudged)} targets met** in this run.{beyond_text} "
           f"Each target row and its peer were measured in {n_rounds} interleaved "
           f"round{'s' if n_rounds > 1 else ''} of this run; a target counts as met only when "
           "it held in every round. A ratio is the row's figure over its peer's (lower is "
           "better: 0.5 means twice as fast as the peer); the figure shown is the median of "
           "the rounds, with the lowest and highest round beside it. Rows are measured in the "
           "default configuration unless their config says otherwise.", "",
           "| target row | figure (median of rounds) | rounds: lowest – highest | target | "
           "verdict |",
           "| --- | --- | --- | --- | --- |"]
    for r in targets:
        rf = round_figures(r)
        if (r.get("target") or "").startswith("ratio"):
            fig = (f"{r['ratio']:.3g}× `{r['peer']}`" if r.get("ratio") is not None
                   else "no peer figure")
        else:
            fig = human(r["value"], r["unit"])
        t = r.get("target") or ""
        held = sum(1 for x in r.get("rounds") or [] if x.get("met"))
        want = r.get("rounds_wanted") or 1
        if r.get("target_met"):
            verdict = f"**met** in all {want} rounds" if want > 1 else "**met**"
        elif r.get("target_met") is False:
            verdict = (f"**not met**: held in {held} of {want} rounds" if want > 1
                       else "**not met**")
            if r["name"] in beyond:
                fl, lo, hi = beyond[r["name"]]
                span = f"{lo:.3g}×" if lo == hi else f"{lo:.3g}× to {hi:.3g}×"
                verdict += (f"; beyond its floor on this host: `{fl}` itself is {span} "
                            f"`{r['peer']}` (judged against the floor: `{r['name']}_vs_floor`)")
        else:
            verdict = "not judged (no figure to judge it by)"
        out.append(f"| `{r['name']}` | {fig} | {spread(r) or '–'} | "
                   f"{t.replace('<=', '≤').replace('>=', '≥')} | {verdict} |")
    for u in unjudged:
        out.append(f"| `{u['name']}` | – | – | {u['target'].replace('<=', '≤')} | "
                   f"not judged: {cell(u['status'])} |")
    out.append("")
    return out


def count_in(text, pattern):
    """The integer a config sentence gives for `pattern` (a regex with one group)."""
    import re
    m = re.search(pattern, text or "")
    return int(m.group(1)) if m else None


def worst_case_markdown(rows):
    """Worst cases: every lateness row's greatest lateness, late cycles and misses."""
    late = [r for r in rows if r["name"].startswith("release_lateness")]
    if not late:
        return []
    out = ["## Worst cases", "",
           "Release lateness of the 1 kHz periodic tasks, over every cycle of every round "
           "(cycles that began one or more whole periods late included). The peer's figure is "
           "its own maximum in the same run.", "",
           "| row | p99 (median of rounds) | greatest lateness | cycles begun ≥ 1 period late | "
           "deadline misses | rounds |",
           "| --- | ---: | ---: | ---: | ---: | ---: |"]
    for r in late:
        rounds = r.get("rounds") or [{"config": r["config"]}]
        over = [count_in(x.get("config"), r"(\d+) cycles began >= 1 period late") for x in rounds]
        miss = [count_in(x.get("config"), r"(\d+) deadline misses") for x in rounds]
        fmt = lambda xs: " + ".join("?" if x is None else str(x) for x in xs)
        out.append(f"| `{r['name']}` | {human(r['value'], 'ns')} | {human(r['max'], 'ns')} | "
                   f"{fmt(over)} | {fmt(miss)} | {len(rounds)} |")
    peer = next((r for r in rows if r["name"] == "peer_sigwait_1khz_lateness_max"), None)
    if peer:
        out.append(f"| `{peer['name']}` (peer) | – | {human(peer['max'] or peer['value'], 'ns')} "
                   f"| – | – | {len(peer.get('rounds') or [1])} |")
    out.extend(["", "Counts are per round, in round order (round 1 + round 2 + ...).", ""])
    return out


def experiments_of(samples_dir):
    """The experiments' data files (DIR/*.json written by chimera-bench)."""
    out = {}
    if samples_dir and Path(samples_dir).is_dir():
        for f in sorted(Path(samples_dir).glob("*.json")):
            try:
                out[f.stem] = json.loads(f.read_text())
            except ValueError as e:
                print(f"run.py: {f.name}: {e}", file=sys.stderr)
    return out


def experiment_markdown(exps):
    """Tables of the experiments' data for docs/benchmarks.md."""
    out = []
    m = exps.get("muf_overload")
    if m:
        us = m["utilisation_pct"]
        out.extend(["## MUF overload experiment", "",
                    "8 periodic tasks (10–200 ms), execution times scaled from 50 % to 150 % "
                    "utilisation, 3 marked critical (35 % of the load); virtual clock, firm "
                    "deadlines (a late job is dropped), 2 s horizon. Percentage of jobs that "
                    "missed their deadline, critical / non-critical"
                    + ("" if m.get("every_job_accounted") else
                       " (WARNING: some jobs were neither met nor missed)") + ".", "",
                    "| policy | " + " | ".join(f"{u} %" for u in us) + " |",
                    "| --- |" + " ---: |" * len(us)])
        for name, d in m["policies"].items():
            cells = [f"{c:.0f} / {n:.0f}" for c, n in zip(d["critical_miss_pct"],
                                                          d["noncritical_miss_pct"])]
            out.append(f"| {name.upper()} | " + " | ".join(cells) + " |")
        out.append("")
    sc = exps.get("scaling_tasks")
    if sc:
        out.extend(median_table(
            "Cost against the number of tasks",
            "Median ns per operation with N ready tasks that never run (see "
            "`bench/kernel/scaling.cpp`).",
            "operation", [f"N = {n}" for n in sc["tasks"]], sc["ops"]))
    sr = exps.get("scaling_rtpus")
    if sr:
        out.extend(median_table(
            "Cost against the number of RTPUs",
            "Median ns per operation with N RTPUs running (see `bench/ipc/scaling_rtpus.cpp`): "
            "`rsem_handoff_rt2` is a remote semaphore hand-off (RT/2) between a task on RTPU 1 "
            "and one on RTPU 2 on the other core while RTPUs 3..N run idle (N = 1: both tasks "
            "on RTPU 1); `msgq_fan_in` is the time per message one receiver on RTPU 1 takes "
            "from N-1 sender RTPUs blocked on a full queue (N = 1: a sender task on RTPU 1). "
            "On a 2-core machine more than two busy RTPUs share the cores. "
            f"{sr.get('config', '')}.",
            "operation", [f"N = {int(n)}" for n in sr["rtpus"]], sr["ops"]))
    sm = exps.get("scaling_msg_size")
    if sm:
        out.extend(median_table(
            "Cost against the message size",
            "Median ns per put+get with nobody waiting, by message size (see "
            "`bench/ipc/scaling_msg_size.cpp`): Chimera's queue in another RTPU's window, "
            "Boost.Interprocess `message_queue` and POSIX mq in one thread, and two `memcpy` "
            "of the size for scale (the copy in and out every queue makes). "
            f"{sm.get('config', '')}"
            + (f"; {sm['posix_mq_note']}" if sm.get("posix_mq_note") else "") + ".",
            "queue", [size_label(int(b)) for b in sm["bytes"]], sm["series"]))
    return out


def median_table(title, prose, first, columns, series):
    """A section with one row of medians (ns) per series, one column per point."""
    out = [f"## {title}", "", prose, "",
           f"| {first} | " + " | ".join(columns) + " |",
           "| --- |" + " ---: |" * len(columns)]
    for name, d in series.items():
        out.append(f"| `{name}` | " + " | ".join(human(v, "ns") for v in d["median"]) + " |")
    out.append("")
    return out


def size_label(b):
    return f"{b // 1024} KiB" if b >= 1024 else f"{b} B"


def curve(ax, xs, d, label, fmt="o-"):
    """One median curve with min–max error bars; None points are left out."""
    pts = [(x, m, lo, hi) for x, m, lo, hi in zip(xs, d["median"], d["min"], d["max"])
           if m is not None]
    if not pts:
        return
    x, med, lo, hi = zip(*pts)
    err = [[max(0.0, a - b) for a, b in zip(med, lo)], [max(0.0, b - a) for a, b in zip(med, hi)]]
    ax.errorbar(x, med, yerr=err, fmt=fmt, capsize=3, label=label, markersize=4)


def lateness_samples(samples_dir):
    """Every periodic loop's release lateness samples (ns, sorted), by loop."""
    lat = sorted(Path(samples_dir).glob("*lateness*.txt")) if samples_dir else []
    loops = {f.stem: sorted(float(x) for x in f.read_text().split()) for f in lat}
    return {name: ns for name, ns in loops.items() if ns}


def lateness_markdown(loops):
    """A table of every periodic loop's release lateness: p50, p99, p99.9, max."""
    rows = []
    for name, ns in loops.items():
        q = lambda p: ns[min(len(ns) - 1, int(p * (len(ns) - 1) + 0.5))]
        rows.append(f"| `{name}` | {len(ns)} | {human(q(0.5), 'ns')} | {human(q(0.99), 'ns')} | "
                    f"{human(q(0.999), 'ns')} | {human(ns[-1], 'ns')} |")
    if not rows:
        return []
    return ["## Release lateness of the 1 kHz loops", "",
            "Every period of each loop in its last round (the rows above give the p99, the "
            "median over the rounds; a cycle that began one or more whole periods late is "
            "sampled with its lateness, in Chimera's loops and in the peer's alike).", "",
            "| loop | periods | p50 | p99 | p99.9 | max |",
            "| --- | ---: | ---: | ---: | ---: | ---: |", *rows, ""]


def plots(rows, lateness, outdir, exps=None):
    """PNG figures; returns (file name, caption) pairs. Needs matplotlib."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("run.py: matplotlib missing (make deps-bench): no plots", file=sys.stderr)
        return []
    outdir.mkdir(parents=True, exist_ok=True)
    made = []

    def save(fig, name, caption):
        fig.tight_layout()
        fig.savefig(outdir / name, dpi=110)
        plt.close(fig)
        made.append((name, caption))

    # Release lateness of every periodic loop that wrote its samples.
    if lateness:
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for name, ns in lateness.items():
            ax.hist([x / 1e3 for x in ns], bins=100, histtype="step", label=f"{name} (n={len(ns)})")
        ax.set_yscale("log")
        ax.set_xlabel("release lateness (µs)")
        ax.set_ylabel("periods")
        ax.set_title("1 kHz periodic release lateness")
        ax.legend(fontsize=8)
        save(fig, "lateness.png", "Release lateness of the 1 kHz loops (log count)")

    # Chimera rows against their peers, with the target where there is one.
    # Peers (rows named peer_*) have no bar here: only Chimera's rows.
    rr = [r for r in rows if r["ratio"] is not None and not r["name"].startswith("peer_")]
    if rr:
        fig, ax = plt.subplots(figsize=(9, 0.5 * len(rr) + 2.2))
        names = [r["name"] for r in rr]
        colors = ["tab:green" if r.get("target_met") else
                  "tab:red" if r.get("target_met") is False else "tab:blue" for r in rr]
        ax.barh(names, [r["ratio"] for r in rr], color=colors)
        for i, r in enumerate(rr):
            rs = [x["ratio"] for x in r.get("rounds") or [] if x.get("ratio") is not None]
            if len(rs) > 1:  # the rounds' spread
                ax.plot([min(rs), max(rs)], [i, i], color="black", lw=1)
            t = r.get("target") or ""
            if t.startswith("ratio <="):
                b = float(t.split()[2])  # "ratio <= B" or "ratio <= B +P/peer"
                ax.plot([b, b], [i - 0.4, i + 0.4], color="black", lw=2)
        for i, r in enumerate(rr):
            ax.annotate(f" {r['ratio']:.3g}x", (r["ratio"], i), va="center", fontsize=8)
        ax.axvline(1, color="grey", lw=0.8, ls="--")
        ax.set_xscale("log")
        lo = min(0.5, min(r["ratio"] for r in rr) / 2)
        ax.set_xlim(lo, max(2.0, max(r["ratio"] for r in rr) * 2))
        ax.set_xlabel("row / its peer, same run — LOWER IS BETTER. Log scale: 1 (dashed) = as "
                      "fast as the peer,\n0.5 = twice as fast, 2 = twice as slow. Thick tick = "
                      "target; thin line = lowest–highest round", fontsize=8)
        ax.set_title("Chimera rows over their peers (green: target met in every round, red: "
                     "not, blue: no target)", fontsize=9)
        ax.invert_yaxis()
        save(fig, "ratios.png", "Chimera rows over their peers, lower is better, log scale "
                                "(green: target met in every round, red: missed in a round, "
                                "blue: no target; thin line: the rounds' spread)")

    # Where the time goes: every peer on one log scale.
    pr = [r for r in rows if r["name"].startswith("peer_") and r["unit"] == "ns"
          and r["value"] and r["value"] > 0]
    if pr:
        fig, ax = plt.subplots(figsize=(8, 0.28 * len(pr) + 1.5))
        ax.barh([r["name"][5:] for r in pr], [r["value"] for r in pr], color="tab:gray")
        for i, r in enumerate(pr):
            ax.annotate(" " + human(r["value"], "ns"), (r["value"], i), va="center", fontsize=6)
        ax.set_xscale("log")
        ax.set_xlabel("ns per operation (median)")
        ax.tick_params(axis="y", labelsize=7)
        ax.invert_yaxis()
        save(fig, "peers.png", "The peers measured in this run")

    exps = exps or {}
    m = exps.get("muf_overload")
    if m:
        us = m["utilisation_pct"]
        fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
        styles = {"rm": "o-", "edf": "s-", "mlf": "^-", "muf": "D-"}
        for ax, key, title in ((axes[0], "critical_miss_pct", "critical tasks"),
                               (axes[1], "noncritical_miss_pct", "non-critical tasks")):
            for name, d in m["policies"].items():
                ax.plot(us, d[key], styles.get(name, "o-"), label=name.upper(), markersize=4)
            ax.axvline(100, color="grey", lw=0.8, ls="--")
            ax.set_title(title)
            ax.set_xlabel("utilisation (%)")
            ax.grid(alpha=0.3)
        axes[0].set_ylabel("jobs missing their deadline (%)")
        axes[1].legend()
        fig.suptitle("Transient overload: deadline misses per policy (virtual clock)")
        save(fig, "muf_overload.png", "MUF overload experiment: misses of critical and "
                  "non-critical jobs under RM, EDF, MLF, MUF from 50 % to 150 % load")
    sc = exps.get("scaling_tasks")
    if sc:
        ns = sc["tasks"]
        fig, ax = plt.subplots(figsize=(8, 4.5))
        for op, d in sc["ops"].items():
            med = d["median"]
            err = [[max(0.0, a - b) for a, b in zip(med, d["min"])],
                   [max(0.0, b - a) for a, b in zip(med, d["max"])]]
            ax.errorbar(ns, med, yerr=err, fmt="o-", capsize=3, label=op, markersize=4)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("tasks alive (ready, never running)")
        ax.set_ylabel("ns per operation (median, min–max)")
        ax.set_title("Scheduler cost against the number of tasks")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, "scaling_tasks.png", "Cost of scheduler operations, yield and spawn "
                  "against the number of tasks (10 to 10,000)")
    sr = exps.get("scaling_rtpus")
    if sr:
        ns = sr["rtpus"]
        fig, ax = plt.subplots(figsize=(8, 4.5))
        labels = {"rsem_handoff_rt2": "remote semaphore hand-off RTPU 1 <-> 2, RT/2 (others idle)",
                  "msgq_fan_in": "one queue, N-1 sender RTPUs: time per message received"}
        for op, d in sr["ops"].items():
            curve(ax, ns, d, labels.get(op, op))
        ax.set_yscale("log")
        ax.set_xticks(ns)
        ax.set_xlabel("RTPUs running (processes, each a kernel)")
        ax.set_ylabel("ns per operation (median, min–max)")
        ax.set_title("Backplane cost against the number of RTPUs")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, "scaling_rtpus.png", "Remote semaphore hand-off between two RTPUs and one "
                  "queue's fan-in against the number of RTPUs running (1 to 8)")
    sm = exps.get("scaling_msg_size")
    if sm:
        xs = sm["bytes"]
        fig, ax = plt.subplots(figsize=(8, 4.5))
        labels = {"chimera_msgq_remote_one_process": "Chimera msgq, queue in another RTPU's window",
                  "boost_message_queue": "Boost.Interprocess message_queue",
                  "posix_mq": "POSIX mq (where msgsize_max allows)",
                  "memcpy_x2": "two memcpy of the size (for scale)"}
        fmts = {"memcpy_x2": "s--"}
        for name, d in sm["series"].items():
            curve(ax, xs, d, labels.get(name, name), fmts.get(name, "o-"))
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(xs)
        ax.set_xticklabels([size_label(int(b)) for b in xs])
        ax.set_xlabel("message size")
        ax.set_ylabel("ns per put+get (median, min–max)")
        ax.set_title("Message put+get with nobody waiting, against the size")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=8)
        save(fig, "scaling_msg_size.png", "Put+get with nobody waiting against the message "
                  "size (24 B to 64 KiB), Chimera beside Boost message_queue and POSIX mq")
    return made


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", default="build-release", help="meson build directory")
    ap.add_argument("--quick", action="store_true", help="few short runs (under a minute)")
    ap.add_argument("--filter", help="only rows matching this regex (and their peers)")
    ap.add_argument("--results", default=str(ROOT / "bench" / "results.json"))
    ap.add_argument("--markdown", default=str(ROOT / "docs" / "benchmarks.md"))
    ap.add_argument("--plots", default=str(ROOT / "docs" / "bench"))
    args = ap.parse_args()

    exe = Path(args.build) / "bench" / "chimera-bench"
    if not exe.exists():
        sys.exit(f"run.py: {exe} not found; build first (`make bench` does)")
    with tempfile.TemporaryDirectory(prefix="chimera-bench-") as tmp:
        rows_path, rest_path = Path(tmp, "rows.json"), Path(tmp, "unmeasured.json")
        samples = Path(tmp, "samples")
        cmd = [str(exe), "--json", str(rows_path), "--unmeasured-json", str(rest_path),
               "--samples", str(samples)]
        if args.quick:
            cmd.append("--quick")
        if args.filter:
            cmd += ["--filter", args.filter]
        load = " ".join(Path("/proc/loadavg").read_text().split()[:3]) if Path("/proc/loadavg").exists() else "?"
        stat0 = cpu_times()
        t0 = time.monotonic()
        rc = subprocess.call(cmd)  # its table goes straight to our stdout
        elapsed = time.monotonic() - t0
        host = host_share(stat0, cpu_times(), load)
        if not rows_path.exists():
            sys.exit(f"run.py: chimera-bench exited with {rc} and wrote no rows")
        rows = json.loads(rows_path.read_text())
        rest = json.loads(rest_path.read_text()) if rest_path.exists() else []

        results = Path(args.results)
        results.parent.mkdir(parents=True, exist_ok=True)
        results.write_text(json.dumps(rows, indent=1, ensure_ascii=False) + "\n")
        md_path = Path(args.markdown)
        md_path.parent.mkdir(parents=True, exist_ok=True)
        plot_dir = Path(args.plots)
        exps = experiments_of(samples)
        if exps:
            exp_path = results.with_name("experiments.json")
            exp_path.write_text(json.dumps(exps, indent=1) + "\n")
        lateness = lateness_samples(samples)
        made = plots(rows, lateness, plot_dir, exps)
        invoked = "/usr/bin/python3 bench/run.py " + " ".join(shlex.quote(a) for a in sys.argv[1:])
        if os.environ.get("MAKELEVEL"):  # started by the Makefile: say so first
            invoked = f"make bench{' QUICK=1' if args.quick else ''}`, i.e. `{invoked}"
        ran = " ".join(shlex.quote(c) for c in cmd).replace(tmp, "$TMP")
        info = machine()
        info["host"] = host
        md = markdown(rows, rest, info, (invoked, ran), args.quick, elapsed)
        md.extend(experiment_markdown(exps))
        md.extend(lateness_markdown(lateness))
        if made:
            md.extend(["## Plots", ""])
            rel = os.path.relpath(plot_dir, md_path.parent)
            for name, caption in made:
                md.extend([f"![{caption}]({rel}/{name})", "", f"*{caption}*", ""])
        md_path.write_text("\n".join(md) + "\n")
    print(f"\nrun.py: wrote {results}, {md_path} and {len(made)} plot(s) in {plot_dir} "
          f"({elapsed:.0f} s)")
    return rc


if __name__ == "__main__":
    sys.exit(main())
