"""``aogm info``: what a log, map or detector file holds (kind, shape, grid, parameters, stats)
and what made it (its ``provenance`` attribute), read through the checking readers."""

from __future__ import annotations

import json

import click


@click.command()
@click.argument("file", metavar="FILE", type=click.Path(dir_okay=False))
@click.option("--json", "as_json", is_flag=True, help="Print the summary as JSON instead of text.")
def info(file: str, as_json: bool) -> None:
    """Print what FILE (a log, map or detector) holds and what made it.

    \b
    log       sensors, scans, source, seed, the truth's grid and checks
    map       mode, grid, layers, runtime, every parameter, the run's stats (EM sweeps,
              clusters, the forward model calibration learned)
    detector  features, network, threshold, metrics, the logs it was trained on

    Then the provenance: the command line, each input's sha256, aogm's version and git
    commit, the libraries' versions, the platform and the time the run started
    ("provenance: none recorded" for files written before aogm recorded it).

    \b
    Example:
      aogm info door_map.h5
    """
    from aogm_cli.io.summary import describe

    summary = describe(file)
    click.echo(json.dumps(summary, indent=2, default=_plain) if as_json else format_summary(summary))


def _plain(value):
    """JSON for what the readers may return besides JSON types (numpy arrays and scalars)."""
    return value.tolist() if hasattr(value, "tolist") else str(value)


# --- text ---------------------------------------------------------------------------------------


def _value(v) -> str:
    if isinstance(v, float):
        return f"{v:.6g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_value(x)}" for k, x in v.items())
    if isinstance(v, list):
        shown = ", ".join(_value(x) for x in v[:8])
        return f"[{shown}{', ...' if len(v) > 8 else ''}]" + (f" ({len(v)} values)" if len(v) > 8 else "")
    return str(v)


def _grid_line(grid: dict | None) -> str:
    if grid is None:
        return "grid: none (no truth)"
    (h, w), (x, y) = grid["shape"], grid["origin"]
    return f"grid: {h} x {w} cells (H x W), resolution {grid['resolution']:g} m, origin ({x:g}, {y:g})"


def format_summary(s: dict) -> str:
    """The summary of ``describe`` as plain text, one item a line."""
    lines = [f"{s['file']}: {s['kind']}"]
    lines += {"log": _log_lines, "map": _map_lines, "detector": _detector_lines}[s["kind"]](s)
    lines += provenance_lines(s["provenance"])
    return "\n".join(lines)


def _log_lines(s: dict) -> list[str]:
    sensor = s["sensor"]
    return [
        f"shape: {s['shape']['scans']} scans x {s['shape']['sensors']} sensors",
        f"source: {s['source']}" + ("" if s["seed"] is None else f" (seed {s['seed']})"),
        f"sensor: {sensor['kind']}, beam width {sensor['beam_width']:.4g} rad, range {sensor['min_range']:g}"
        f"-{sensor['max_range']:g} m, noise sigma {sensor['noise_sigma']:g} m",
        _grid_line(s["grid"]),
        *([] if s["checks"] is None else [f"checks: {', '.join(s['checks']) or 'none'}"]),
    ]


def _map_lines(s: dict) -> list[str]:
    from aogm_cli.report.calibration_table import calibration_table

    h, w = s["shape"]["height"], s["shape"]["width"]
    lines = [
        f"mode: {s['mode']}",
        f"source log: {s['source_log'] or '(not recorded)'}",
        f"shape: {h} x {w}",
        _grid_line(s["grid"]),
        f"layers: {', '.join(s['layers'])}",
        f"cells: {s['observed_cells']} observed of {h * w}, {s['occupied_cells']} believed occupied (p > 0.5)",
        f"runtime: {s['runtime_s']:.3f} s",
        "parameters:",
        *(f"  {k}: {_value(v)}" for k, v in sorted(s["params"].items())),
    ]
    for key, title in (("plan", "plan (decided before the first stage)"), ("learned", "learned (from the log or given)")):
        if s.get(key):
            lines += [f"{title}:", *(f"  {k}: {' > '.join(v) if k == 'stages' else _learned_value(k, v)}"
                                     for k, v in s[key].items())]
    stats = dict(s["stats"])
    calibration = stats.pop("calibration", None)
    lines += ["stats:", *(f"  {k}: {_value(v)}" for k, v in sorted(stats.items()))] if stats else ["stats: none"]
    if isinstance(calibration, dict):
        try:
            table = calibration_table(calibration)
        except (KeyError, TypeError, ValueError):  # a record of another shape: shown as it is
            table = _value(calibration)
        lines += ["calibration (the forward model learned from the log):", *("  " + t for t in table.splitlines())]
    return lines


def _learned_value(key: str, value) -> str:
    """A value of the map's plan or ``learned`` record as text: the lobe's record in words (``lobe_line``: its
    echo rate by angle, the echoes explained, the lobe), the rest as it is (``--json`` keeps every count)."""
    from aogm_cli.report.calibration_table import lobe_line

    if key == "lobe" and isinstance(value, dict):
        try:
            return lobe_line(value).removeprefix("the lobe: ")
        except (KeyError, TypeError, ValueError, ZeroDivisionError):  # a record of another shape: as it is
            pass
    return _value(value)


def _detector_lines(s: dict) -> list[str]:
    from aogm_cli.cli.train import format_metrics

    f = s["features"]
    lines = [
        f"shape: {'-'.join(map(str, s['shape']))} (features, hidden, output)",
        f"features: {f['count']} (ring neighbours {f['ring_neighbours']}, time neighbours {f['time_neighbours']}, "
        f"differences {f['differences']}, missing flags {f['missing_flags']})",
        f"network: {s['network'] or '(not recorded)'}",
        f"threshold: {s['threshold']:.4g}",
        "metrics:",
    ]
    try:
        lines += ["  " + t for t in format_metrics(s["metrics"]).splitlines()]
    except (KeyError, TypeError, ValueError):
        lines.append(f"  {_value(s['metrics'])}")
    logs = s["training_logs"]
    if not logs:
        return [*lines, "training logs: not recorded"]
    lines.append("training logs:")
    for part, entries in logs.items():
        for e in entries if isinstance(entries, list) else []:
            e = e if isinstance(e, dict) else {"file": e}
            extra = ", ".join(f"{k} {_value(e[k])}" for k in ("world", "realistic", "seed", "scans") if k in e)
            lines.append(f"  {part}: {e.get('file')}" + (f" ({extra})" if extra else ""))
    return lines


def provenance_lines(record: dict | None) -> list[str]:
    """A provenance record (``io.provenance``) as text lines."""
    if record is None:
        return ["provenance: none recorded"]
    import shlex

    command = record.get("command")
    libraries = record.get("libraries") or {}
    commit = record.get("git_commit")
    lines = [
        "provenance:",
        f"  command: {shlex.join(command) if isinstance(command, list) else command}",
        "  inputs:" if record.get("inputs") else "  inputs: none",
        *(f"    {i.get('path')}  sha256 {i.get('sha256')}" for i in record.get("inputs") or [] if isinstance(i, dict)),
        f"  aogm: {record.get('aogm_version')}" + (f" (git {commit})" if commit else ""),
        "  libraries: " + ", ".join(f"{k} {v}" for k, v in libraries.items()),
        f"  platform: {record.get('platform')}, Python {record.get('python')}",
        f"  time: {record.get('time')}",
    ]
    return lines
