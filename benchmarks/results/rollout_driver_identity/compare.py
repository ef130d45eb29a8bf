"""Compare two runs' metrics.csv column by column, row by row, as text (exact equality);
columns that time the run are left out. Prints the rows, the columns that differ and a verdict.

Usage: python compare.py BEFORE/metrics.csv AFTER/metrics.csv
"""

from __future__ import annotations

import csv
import sys

TIMING = ("wall_time", "env_steps_per_s")


def read(path: str) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def moved(before: str, after: str) -> tuple[int, int, list[str], list[str]]:
    """(rows before, rows after, columns in one file only, columns whose values differ)."""
    cols_b, rows_b = read(before)
    cols_a, rows_a = read(after)
    only = sorted(set(cols_b) ^ set(cols_a))
    shared = [c for c in cols_b if c in cols_a and c not in TIMING]
    same_rows = len(rows_b) == len(rows_a)
    diff = [c for c in shared if not same_rows
            or any(rb[c] != ra[c] for rb, ra in zip(rows_b, rows_a, strict=True))]
    return len(rows_b), len(rows_a), only, diff


def main() -> int:
    before, after = sys.argv[1:3]
    n_b, n_a, only, diff = moved(before, after)
    same_order = read(before)[0] == read(after)[0]
    ok = n_b == n_a and not only and not diff and same_order
    print(f"rows {n_b} {n_a}; columns in one file only: {only}; column order same: "
          f"{same_order}; moved columns: {diff} -> {'IDENTICAL' if ok else 'DIFFERENT'}")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
