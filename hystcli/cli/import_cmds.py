"""`hyst import`: foreign logs (any delimited text, gzip or not) to run CSVs.

Parses the options into an :class:`~hystcli.io.importer.ImportMapping` and
:class:`~hystcli.io.importer.ImportOptions`, converts every file with
:func:`hystcli.io.importer.convert` before writing any, then writes the runs atomically and renders
what was done (rows, rate, ranges, gain, zeroing, drift, warnings).
"""
from __future__ import annotations

import contextlib
import dataclasses
import json
import math
from enum import Enum
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..io import importer  # numpy only (its filter imports scipy when it runs): the presets name the options
from ..errors import DataError
from ..io import all_or_none, check_not_input
from .app import (FormatOpt, OutputFormat, QuietOpt, command, echo_json, info, only_formats, option_errors, reading,
                  usage_error, warn)


class ZeroMode(str, Enum):
    none = "none"
    first = "first"
    mean = "mean"


class TimeRepair(str, Enum):
    error = "error"
    drop = "drop"


def _mapping(preset: Optional[str], mapping_file: Optional[Path], spec: Optional[str], sep: Optional[str],
             comment: Optional[str], skip: Optional[int], rate: Optional[float],
             header_patterns: list[str]) -> importer.ImportMapping:
    """The mapping the options describe. A malformed option value is a usage error (exit 2); a
    malformed --mapping file is bad data (exit 1)."""
    if preset is not None and mapping_file is not None:
        usage_error("give --preset or --mapping, not both", "--preset")
    if preset is None and mapping_file is None and spec is None:
        usage_error("say how to read the files: --preset NAME, --mapping FILE.json or "
                    "--map t=time_s,q1=knob_deg,...", "--map")
    with option_errors("--map"):
        extra = importer.parse_map_spec(spec) if spec is not None else ()
    if preset is not None:
        with option_errors("--preset"):
            base = importer.get_preset(preset)
    elif mapping_file is not None:
        base = importer.load_mapping(mapping_file)
    else:
        base = None
    changes: dict = {}
    if sep is not None:
        with option_errors("--sep"):
            changes["separator"] = importer.parse_separator(sep)
    if comment is not None:
        changes["comment"] = comment or None
    if skip is not None:
        changes["skip"] = skip
    if rate is not None:
        changes["rate"] = rate
    with option_errors("--meta-from-header"):
        pats = tuple(importer.parse_meta_pattern(p) for p in header_patterns)
    # what the options combine to is checked as a whole (a time column, no target twice)
    with contextlib.nullcontext() if mapping_file is not None else option_errors("--map"):
        if base is None:
            # a mapping of your own: separator, header row and comment lines found from the file
            auto = {"separator": importer.AUTO, "comment": importer.AUTO}
            return importer.ImportMapping(columns=tuple(extra), meta_from_header=pats, name="--map",
                                          **{**auto, **changes})
        m = base.with_columns(extra)
        return dataclasses.replace(m, meta_from_header=m.meta_from_header + pats, **changes)


def _fmt_range(lo: float, hi: float) -> str:
    return f"{lo:.4g} .. {hi:.4g}"


def _render(rep: importer.ImportReport, meta: dict, out: Path) -> list[str]:
    lines = [f"{rep.source} -> {out}  [{rep.mapping}]",
             f"  rows {rep.rows_read} read" + (f", {rep.rows_dropped} dropped" if rep.rows_dropped else "")
             + f", {rep.rows_out} written; {rep.duration:.4g} s at {rep.rate_in:.6g} Hz"
             + (f" -> {rep.rate_out:.6g} Hz" + (" (anti-alias low-pass)" if rep.anti_aliased else "")
                if rep.resampled else "")]
    lines.append("  ranges: " + "; ".join(f"{k} {_fmt_range(*v)}" for k, v in rep.ranges.items()))
    if meta:
        lines.append("  meta: " + " ".join(f"{k}={v}" for k, v in meta.items() if k != "import"))
    for k in rep.knobs:
        bits = []
        if k.gain is not None:
            bits.append(f"gain y/q {k.gain:+.3f} as read" + (", output flipped" if k.flipped else ""))
        elif k.flipped:
            bits.append("output flipped")
        bits.append("zero: " + (", ".join(f"{n} {v:.4g} subtracted" for n, v in k.zero.items()) if k.zero else "none"))
        if k.drift is not None:
            bits.append(f"drift {k.drift:+.3g} deg/s" + (" (removed)" if k.detrended else ""))
        lines.append(f"  knob {k.knob}: " + "; ".join(bits))
    return lines


@command(
    "import", "Convert foreign logs into run CSVs by a column mapping",
    help=(
        "Convert foreign logs (delimited text, .gz read transparently) into run CSVs through a column "
        "mapping: a built-in --preset, a --mapping JSON file (docs/import.md), or --map "
        "target=column[:scale|unit[:offset]],...: a column by its header name or its number "
        "(from 1), then a unit (ms, us, min to s; rad, rev to deg; A, uA to mA) or a scale (value = "
        "raw*scale + offset; scales may be fractions such as 360/8192). With --map alone the "
        "separator (comma, tab, semicolon or whitespace), the header row and the # or % comment "
        "lines are found from the file. --map entries add to or replace a preset's.\n\n"
        "Metadata comes from the preset, --meta-from-header KEY=REGEX (first group) or a REGEX with "
        "named groups, and --meta key=value (wins; {key} is replaced by header metadata).\n\n"
        "Conditioning: --zero none|first|mean (default none: offsets between runs of a session are "
        "real information, and the model absorbs a constant zero), --flip-output when the output "
        "falls as the input rises (reported), --resample HZ (anti-alias low-pass when lowering the "
        "rate), --detrend (remove the output drift; reported either way), --time-repair drop "
        "(default: an error on non-increasing time).\n\n"
        "The current is written in mA, converted from the unit the log states (metadata "
        "current_unit: A, mA or uA; the mrdlab preset states A).\n\n"
        "Examples (from the repository root):\n\n"
        "    hyst import my_log.tsv --map t=time_ms:ms,q1=knob:rad,y1=tip_deg,c1=I:A -o run.csv\n\n"
        "    hyst import tests/data/mrdlab/load_freq/41_first6000.TXT.gz --preset mrdlab -o run41.csv\n\n"
        "    hyst import tests/data/mrdlab/load_freq/41_first6000.TXT.gz --map t=1,q1=2:360/8192,y1=5:0.09,c1=4 "
        "--comment '%' --meta current_unit=A -o run.csv\n\n"
        "    hyst import tests/data/mrdlab/load_freq/*.TXT.gz --preset mrdlab --resample 200 --out-dir ."
    ),
)
def import_(
    raw: Annotated[list[Path], typer.Argument(metavar="RAW", help="Raw log files (text or gzip).")],
    output: Annotated[Optional[Path], typer.Option("--output", "-o", help="Output run CSV (one input).")] = None,
    out_dir: Annotated[Optional[Path], typer.Option(
        "--out-dir", help="Folder for many inputs: RAW name without .gz and extension, plus .csv.")] = None,
    preset: Annotated[Optional[str], typer.Option(
        "--preset", help=f"Built-in mapping: {', '.join(importer.PRESETS)}.")] = None,
    mapping_file: Annotated[Optional[Path], typer.Option(
        "--mapping", help="Mapping JSON file (docs/import.md).")] = None,
    spec: Annotated[Optional[str], typer.Option(
        "--map", help="target=column[:scale|unit[:offset]],... e.g. t=time_ms:ms,q1=knob_deg,c1=I:A or "
                      "t=1:0.001,q1=2:360/8192,y1=5:0.09,c1=4")] = None,
    sep: Annotated[Optional[str], typer.Option(
        "--sep", help="Field separator: a character, 'tab', 'whitespace' or 'auto' (default: auto with --map "
                      "alone, else the mapping's).")] = None,
    comment: Annotated[Optional[str], typer.Option(
        "--comment", help="Comment prefix of header lines ('' for none; default: # or % with --map alone, "
                          "else the mapping's).")] = None,
    skip: Annotated[Optional[int], typer.Option("--skip", min=0, help="Lines to skip at the top.")] = None,
    rate: Annotated[Optional[float], typer.Option(
        "--rate", help="Sample rate (Hz) when the log has no time column.")] = None,
    meta: Annotated[Optional[list[str]], typer.Option(
        "--meta", help="key=value metadata (repeatable).")] = None,
    meta_from_header: Annotated[Optional[list[str]], typer.Option(
        "--meta-from-header", help="KEY=REGEX (first group) or REGEX with (?P<key>...) groups, "
                                   "searched in the header lines (repeatable).")] = None,
    zero: Annotated[ZeroMode, typer.Option(
        "--zero", help="Subtract from each input/output column: none, its first sample, or its mean.")
    ] = ZeroMode.none,
    flip_output: Annotated[Optional[bool], typer.Option(
        "--flip-output/--no-flip-output", help="Negate the output (y, r); default: the mapping's choice.")] = None,
    resample_hz: Annotated[Optional[float], typer.Option(
        "--resample", help="Resample onto a uniform grid at this rate (Hz).")] = None,
    detrend: Annotated[bool, typer.Option("--detrend", help="Remove the output's linear drift.")] = False,
    time_repair: Annotated[TimeRepair, typer.Option(
        "--time-repair", help="Non-increasing time stamps: error, or drop those rows.")] = TimeRepair.error,
    decimals: Annotated[Optional[int], typer.Option(
        "--decimals", min=0, max=15, help="Round values to this many decimals (smaller files).")] = None,
    show_mapping: Annotated[bool, typer.Option(
        "--show-mapping", help="Print the mapping as JSON (a start for your own) and exit.")] = False,
    fmt: FormatOpt = OutputFormat.table,
    quiet: QuietOpt = False,
) -> None:
    only_formats(fmt, "import", OutputFormat.table, OutputFormat.json)
    if rate is not None and not 0 < rate < math.inf:
        usage_error("must be a positive number of Hz", "--rate")
    if resample_hz is not None and not 0 < resample_hz < math.inf:
        usage_error("must be a positive number of Hz", "--resample")
    mapping = _mapping(preset, mapping_file, spec, sep, comment, skip, rate, meta_from_header or [])
    if show_mapping:
        typer.echo(json.dumps(importer.mapping_to_dict(mapping), indent=2))
        return
    if (output is None) == (out_dir is None):
        usage_error("give -o OUT.csv (one input) or --out-dir DIR", "--output")
    if output is not None and len(raw) > 1:
        usage_error(f"{len(raw)} inputs: use --out-dir DIR", "--output")
    if out_dir is not None and not out_dir.is_dir():
        raise DataError(f"{out_dir}: no such folder")
    targets = [output] if output is not None else [out_dir / importer.output_name(p) for p in raw]
    seen: dict[Path, Path] = {}
    for src, dst in zip(raw, targets):
        key = dst.resolve()
        if key in seen:
            usage_error(f"{seen[key]} and {src} would both be written to {dst}", "--out-dir")
        seen[key] = src
        check_not_input(dst, raw)
    with option_errors("--meta"):
        meta_values = dict(importer.parse_meta_option(m) for m in (meta or []))
    options = importer.ImportOptions(
        zero=zero.value, flip_output=flip_output, resample=resample_hz, detrend=detrend,
        time_repair=time_repair.value, decimals=decimals, meta=meta_values)

    # convert everything first, then write all or none: a bad file leaves no output at all
    done = []
    for p in raw:
        with reading(p, quiet) as progress:
            done.append(importer.convert(p, mapping, options, progress=progress))
    with all_or_none() as pending:
        for dst, d in zip(targets, done):
            pending.write_run(dst, d.run, inputs=raw)

    if fmt == OutputFormat.json:
        echo_json([dict(d.report.to_dict(), output=str(dst), meta=dict(d.run.meta)) for d, dst in zip(done, targets)])
    elif not quiet:
        for d, dst in zip(done, targets):
            typer.echo("\n".join(_render(d.report, dict(d.run.meta), dst)))
    if not quiet:
        for d in done:
            for w in d.report.warnings:
                warn(f"{d.report.source}: {w}")
        info(f"wrote {len(targets)} run file(s)", quiet)
