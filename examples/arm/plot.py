#!/usr/bin/env python3
"""The pick-and-place demo's plot: joint angles against their references
and the contact force, with the module switches marked.

usage: plot.py SAMPLES.csv OUT.png  (samples written by chimera-arm-monitor --csv)"""
import csv
import sys

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt


def main(src, out):
    cols, switches = {}, []
    with open(src, newline="") as f:
        rows = csv.reader(f)
        head = next(rows)
        for h in head:
            cols[h] = []
        for r in rows:
            if r and r[0] == "#switch":
                switches.append((float(r[1]), float(r[2]), r[3]))
            elif len(r) == len(head):
                for h, v in zip(head, r):
                    cols[h].append(float(v))
    if not cols.get("t"):
        sys.exit("plot.py: no samples in " + src)
    t = cols["t"]
    fig, (ax1, ax2) = plt.subplots(2, 1, sharex=True, figsize=(10, 6.5))
    for j, colour in (("1", "tab:blue"), ("2", "tab:orange")):
        ax1.plot(t, cols["q" + j], color=colour, label="q" + j)
        ax1.plot(t, cols["q" + j + "_ref"], color=colour, linestyle="--", label="q" + j + " reference")
    ax1.set_ylabel("joint angle (rad)")
    ax1.legend(loc="upper right", fontsize="small", ncol=2)
    ax2.plot(t, cols["fz"], color="tab:red", label="contact force Fz (F/T sensor)")
    ax2.plot(t, cols["fgrip"], color="tab:green", label="grip force")
    ax2.set_ylabel("force (N)")
    ax2.set_xlabel("time (s)")
    ax2.legend(loc="upper right", fontsize="small")
    for ax in (ax1, ax2):
        for ts, cost, phase in switches:
            ax.axvline(ts, color="grey", linestyle=":", linewidth=1)
    for ts, cost, phase in switches:
        ax1.annotate(f"{phase}\n{cost:.1f} cyc", (ts, 1.0), xycoords=("data", "axes fraction"),
                     fontsize="x-small", va="top", ha="left", color="dimgrey")
    fig.suptitle("Chimera pick-and-place: joints, contact force and module switches")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
