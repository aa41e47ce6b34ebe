"""Smoke test of chimera-bench (meson suite `bench`): run the whole suite with
--quick (every target row and its peer in 3 rounds, as `make bench` does)
and check that it exits cleanly and writes well-formed rows. It checks no
figure against a threshold: shared machines make timings noise."""
import json
import math
import os
import re
import subprocess
import sys
import tempfile

REQUIRED = {"name", "unit", "value", "min", "max", "peer", "peer_value", "ratio",
            "paper_value", "config"}
ALWAYS = {"port_switch", "peer_fiber_switch", "peer_sem_wait_post",
          "peer_pthread_create_join", "peer_signal_self", "msgq_putget_24b_remote_one_process",
          "msg_put_24b_remote_one_process", "msg_get_24b_remote_one_process",
          "sched_ops_10k_over_10"}
# Renamed: rows measured in one process say so; these names must not return.
RETIRED = {"msgq_putget_24b_xrtpu", "msg_put_24b_remote", "msg_get_24b_remote",
           "msgq_putget_64k_xrtpu"}
ROUNDS = 3


def number_or_null(v):
    return v is None or (isinstance(v, (int, float)) and math.isfinite(v))


def main():
    exe = sys.argv[1]
    with tempfile.TemporaryDirectory() as tmp:
        rows_path = os.path.join(tmp, "rows.json")
        rest_path = os.path.join(tmp, "unmeasured.json")
        proc = subprocess.run([exe, "--quick", "--json", rows_path,
                               "--unmeasured-json", rest_path],
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True, timeout=280)
        print(proc.stdout)
        assert proc.returncode == 0, f"chimera-bench exited with {proc.returncode}"
        rows = json.load(open(rows_path))
        rest = json.load(open(rest_path))
    assert isinstance(rows, list) and rows, "no rows"
    names = [r["name"] for r in rows]
    assert len(names) == len(set(names)), "duplicate row names"
    for r in rows:
        missing = REQUIRED - r.keys()
        assert not missing, f"{r.get('name')}: missing {missing}"
        assert re.fullmatch(r"[a-z0-9_]+", r["name"]), r["name"]
        assert isinstance(r["value"], (int, float)) and math.isfinite(r["value"]), r
        for k in ("min", "max", "peer_value", "ratio", "paper_value"):
            assert number_or_null(r[k]), f"{r['name']}.{k} = {r[k]!r}"
        if r["peer_value"] and r["ratio"] is not None:
            assert math.isclose(r["ratio"], r["value"] / r["peer_value"], rel_tol=1e-3), r
        if r["min"] is not None and r["max"] is not None:
            assert r["min"] <= r["value"] <= r["max"], r
        assert r["config"], f"{r['name']}: no config stated"
        # Every round's figure is there; a target is met only in every round.
        rounds = r["rounds"]
        assert rounds and all(number_or_null(x["value"]) for x in rounds), r["name"]
        if r.get("target"):
            assert r["rounds_wanted"] == ROUNDS, f"{r['name']}: {r['rounds_wanted']} rounds"
            if r["target_met"]:
                assert len(rounds) == ROUNDS and all(x["met"] for x in rounds), r["name"]
    assert ALWAYS <= set(names), f"missing rows: {ALWAYS - set(names)}"
    assert not RETIRED & (set(names) | {u["name"] for u in rest}), RETIRED & set(names)
    # A row is either measured or listed with the reason it is not.
    assert not set(names) & {u["name"] for u in rest}
    failed = [u for u in rest if u["status"].startswith("failed")]
    assert not failed, failed
    print(f"bench smoke: {len(rows)} rows measured, {len(rest)} listed without a figure")


if __name__ == "__main__":
    main()
