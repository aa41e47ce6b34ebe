"""Unit test of the report's summary (bench/run.py, meson suite `bench`):
a target row that misses is said to lie beyond its in-run floor only when
the floor itself misses the same bound against the same peer in every round."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import run  # noqa: E402


def row(name, peer, target=None, met=None, rounds=()):
    return {"name": name, "unit": "ns", "value": 1.0, "peer": peer, "ratio": rounds[0] if rounds else None,
            "target": target, "target_met": met, "rounds_wanted": 3,
            "rounds": [{"round": i + 1, "ratio": x, "met": None if met is None else x <= 0.8}
                       for i, x in enumerate(rounds)]}


def summary(floor_rounds, target_met=False, floor_peer="peer_mq"):
    rows = [row("wake", "peer_mq", "ratio <= 0.8", target_met, (0.9, 0.92, 0.95)),
            row("wake_vs_floor", "peer_futex", "ratio <= 1.1", False, (1.1, 1.12, 1.15)),
            row("peer_futex", floor_peer, None, None, floor_rounds),
            row("peer_mq", None)]
    lines = run.summary_markdown(rows, [])
    return "\n".join(lines), next(l for l in lines if l.startswith("| `wake` "))


def main():
    text, wake = summary((0.81, 0.82, 0.83))
    assert "beyond its floor on this host: `peer_futex` itself is 0.81× to 0.83× `peer_mq`" in wake, wake
    assert "1 of those not met lies beyond the in-run floor" in text, text
    # The floor met the bound in one round: the target is reachable in principle.
    text, wake = summary((0.79, 0.82, 0.83))
    assert "beyond" not in wake and "beyond the in-run floor" not in text, wake
    # A met target is never qualified.
    text, wake = summary((0.81, 0.82, 0.83), target_met=True)
    assert "beyond" not in wake and "**met**" in wake, wake
    # A floor measured against another peer says nothing about this target.
    text, wake = summary((0.81, 0.82, 0.83), floor_peer="peer_other")
    assert "beyond" not in wake, wake
    assert run.ratio_bound("ratio <= 1.1") == 1.1 and run.ratio_bound("value <= 2") is None
    print("report summary: 5 checks passed")


if __name__ == "__main__":
    main()
