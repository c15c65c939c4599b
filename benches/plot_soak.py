"""Draws the soak benchmark's CSV (cargo bench --bench soak) into one PNG of four panels:
resident memory, frames dropped per 10 s, frame-to-publish p50/p99, objects tracked.

    python3 benches/plot_soak.py target/soak.csv soak.png      (needs matplotlib)
"""

import csv
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def main(csv_path, png_path):
    with open(csv_path, newline="") as f:
        rows = [{k: float(v) for k, v in row.items()} for row in csv.DictReader(f)]
    if not rows:
        sys.exit(f"{csv_path} has no samples")
    minutes = [r["elapsed_s"] / 60 for r in rows]
    fig, axes = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    axes[0].plot(minutes, [r["rss_mib"] for r in rows], color="tab:blue")
    axes[0].set_ylabel("RSS (MiB)")
    axes[0].set_ylim(bottom=0)
    axes[1].plot(
        minutes,
        [100 * r["frames_dropped"] / max(r["frames_in"], 1) for r in rows],
        color="tab:red",
    )
    axes[1].set_ylabel("dropped per 10 s (%)")
    axes[1].set_ylim(bottom=0)
    axes[2].plot(minutes, [r["f2p_p50_ms"] for r in rows], label="p50")
    axes[2].plot(minutes, [r["f2p_p99_ms"] for r in rows], label="p99")
    axes[2].set_ylabel("frame-to-publish (ms)")
    axes[2].set_ylim(bottom=0)
    axes[2].legend(loc="upper right")
    axes[3].plot(minutes, [r["objects"] for r in rows], color="tab:green")
    axes[3].set_ylabel("objects tracked")
    axes[3].set_xlabel("minutes")
    axes[3].set_ylim(bottom=0)
    fig.suptitle("tacmesh run, demo scene: soak")
    fig.tight_layout()
    fig.savefig(png_path, dpi=80)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
