"""Which error of a world does what: world files with its errors: section taken apart.

    python bench/error_ablation.py worlds/*_pioneer.yaml -o out/ablation [--passable-only]

For each world W writes DIR/W_none.yaml (no errors), DIR/W_<error>.yaml (that error alone),
DIR/W_no_<error>.yaml (every error but that one) and DIR/W_all.yaml (the section as it is), with
the name set to the file's stem. The random odometry errors (translation, rotation,
rotation_per_metre_deg) count as one error, ``odometry``, and the systematic ones
(heading_bias_per_metre_deg, turn_bias) as another, ``odometry_bias``. ``--passable-only`` drops
every check but the passable ones (for mappers older than blocked checks; the arrays are the
same). Simulate and map them, then table them with bench/planner_table.py.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import yaml

SYSTEMATIC = ("heading_bias_per_metre_deg", "turn_bias")


def split(errors: dict) -> dict[str, dict]:
    """The errors: section as separate errors, each a section of its own."""
    parts = {}
    for key, value in errors.items():
        if key != "odometry":
            parts[key] = {key: value}
            continue
        random = {k: v for k, v in value.items() if k not in SYSTEMATIC}
        systematic = {k: v for k, v in value.items() if k in SYSTEMATIC}
        if random:
            parts["odometry"] = {"odometry": random}
        if systematic:
            parts["odometry_bias"] = {"odometry": systematic}
    return parts


def joined(parts: list[dict]) -> dict:
    out: dict = {}
    for part in parts:
        for key, value in part.items():
            out[key] = {**out[key], **value} if key == "odometry" and key in out else value
    return out


def variants(errors: dict) -> dict[str, dict]:
    parts = split(errors)
    out = {"none": {}}
    out.update({name: part for name, part in parts.items()})
    out.update({f"no_{name}": joined([p for n, p in parts.items() if n != name]) for name in parts})
    out["all"] = errors
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("worlds", nargs="+")
    ap.add_argument("-o", "--out", required=True)
    ap.add_argument("--passable-only", action="store_true")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    for path in map(Path, a.worlds):
        raw = yaml.safe_load(path.read_text())
        errors = raw.pop("errors", None) or {}
        if a.passable_only:
            raw["checks"] = [c for c in raw.get("checks", []) if "passable" in c]
        for name, section in variants(errors).items():
            stem = f"{path.stem}_{name}"
            world = {**raw, "name": stem, **({"errors": section} if section else {})}
            (out / f"{stem}.yaml").write_text(yaml.safe_dump(world, sort_keys=False))


if __name__ == "__main__":
    main()
