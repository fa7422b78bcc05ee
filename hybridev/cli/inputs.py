"""Options shared by the subcommands: the vehicle, a logger's columns, logged traces, outputs.

* ``--coastdown A B C MASS``, ``--heater {auto,ptc,heat_pump}`` and ``--capacity-kwh``:
  the vehicle (:meth:`hybridev.VehicleParams.from_coastdown`; ``--heater`` sets its
  ``heater_kind``, default ``auto``: learned from the trips at fit, and needs
  ``--coastdown``); a saved model carries its vehicle (with the learned heater),
  so with ``--model`` a different road load or a declared heater that differs is an
  error and ``--capacity-kwh`` only changes how energy maps to SoC.
* ``--columns old=new,...`` and/or ``--columns-file map.csv`` (two columns
  ``old,new``): rename a logger's columns to the contract before anything
  else. The same mapping applies to the time series (columns it lacks are
  skipped there).
* ``--soc-initial S``: fills a missing or empty ``soc_initial`` (a logger
  without SoC). With ``energy_kwh`` measured, the SoC at departure only enters
  as a network input and in ``soc_final_*``.
* ``--timeseries FILE``: logged traces; missing trip summaries
  (``distance_km``, ``avg_speed_kmh``, ``temperature_c``, ``soc_initial``) are
  derived from them, and the physics runs on them.

Every check runs before any work; errors are ``ValueError`` (exit code 2).
"""

from __future__ import annotations

import argparse

__all__ = ["TABLE_SUFFIXES", "add_input_arguments", "add_vehicle_arguments",
           "apply_columns", "column_mapping",
           "fill_soc_initial", "hint_missing_soc", "model_with_vehicle", "print_data_quality",
           "read_trips", "report_rejected", "vehicle_from_args"]

TABLE_SUFFIXES = (".csv", ".parquet", ".pq")


def add_vehicle_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--coastdown", type=float, nargs=4, default=None,
                   metavar=("A_N", "B_N_PER_KMH", "C_N_PER_KMH2", "MASS_KG"),
                   help="your vehicle from its coast-down road load F = A + B v + C v^2 "
                        "(v in km/h) and test mass (default: the paper's vehicle)")
    p.add_argument("--heater", choices=("auto", "ptc", "heat_pump"), default=None,
                   help="cabin heater of a --coastdown vehicle: auto (the default: learned "
                        "from the measured trips when fitting; PTC unless they show a heat "
                        "pump's shape), ptc (resistive) or heat_pump (COP falls with the "
                        "cold), if the spec sheet says")
    p.add_argument("--capacity-kwh", type=float, default=None,
                   help="usable battery capacity, kWh (maps energy to SoC; default: the "
                        "vehicle's, 75 kWh for the paper's)")


def add_input_arguments(p: argparse.ArgumentParser, *, timeseries: bool = True) -> None:
    p.add_argument("--columns", default=None, metavar="OLD=NEW,...",
                   help="rename your logger's columns to the contract first, e.g. "
                        "mean_speed_kmh=avg_speed_kmh,e_batt_net_kwh=energy_kwh; map the "
                        "trip start (date and time, year first) to start_time so that "
                        "trips after a short stop start with a warm cabin (parked_min)")
    p.add_argument("--columns-file", default=None, metavar="FILE",
                   help="the same mapping as a .csv with columns old,new")
    p.add_argument("--soc-initial", type=float, default=None, metavar="S",
                   help="SoC at departure, [0, 1], for rows without one (a logger without "
                        "SoC: with energy_kwh measured it is only a network input)")
    if timeseries:
        p.add_argument("--timeseries", default=None, metavar="FILE",
                       help="logged time series, .csv or .parquet (trip_id, t_s, speed_kmh; "
                            "optional elevation_m or grade_pct, amb_temp_c, soc): the physics "
                            "runs on the traces and missing trip summaries are derived")


def vehicle_from_args(args: argparse.Namespace):
    """The :class:`~hybridev.VehicleParams` of ``--coastdown`` / ``--heater`` / ``--capacity-kwh``."""
    from hybridev.physics.params import VehicleParams

    cap = getattr(args, "capacity_kwh", None)
    extra = {} if cap is None else {"battery_capacity_kwh": cap}
    cd = getattr(args, "coastdown", None)
    heater = getattr(args, "heater", None)
    if heater is not None:
        if cd is None:
            raise ValueError(f"--heater={heater!r} needs --coastdown A B C MASS: the paper's "
                             "vehicle (the default) uses the paper's four HVAC power bands, "
                             "which have no heater kind")
        extra["heater_kind"] = heater
    if cd is not None:
        return VehicleParams.from_coastdown(*cd, **extra)
    return VehicleParams(**extra)


def model_with_vehicle(model, args: argparse.Namespace):
    """Check ``--coastdown`` against a loaded model; apply ``--capacity-kwh``."""
    import dataclasses

    veh = model._vehicle()
    if getattr(args, "coastdown", None) is not None or getattr(args, "heater", None):
        want = vehicle_from_args(args)
        fields = [f.name for f in dataclasses.fields(veh)
                  if f.name not in ("battery_capacity_kwh", "source")]
        if want.heater_kind == "auto":  # learned at fit: any saved kind matches
            fields.remove("heater_kind")
        if any(getattr(want, f) != getattr(veh, f) for f in fields):
            raise ValueError(f"--coastdown={args.coastdown!r} --heater="
                             f"{getattr(args, 'heater', None)!r} does "
                             f"not match the saved model's vehicle ({veh.source}, heater "
                             f"{veh.heater_kind}); the road load and heater are fixed when "
                             "fitting: re-fit with them, or leave them out here")
    if getattr(args, "capacity_kwh", None) is not None:
        model.vehicle = dataclasses.replace(veh, battery_capacity_kwh=args.capacity_kwh)
        model._check_params()
    return model


def column_mapping(args: argparse.Namespace) -> dict[str, str]:
    """``--columns`` and ``--columns-file`` as one ``{old: new}`` dict."""
    mapping: dict[str, str] = {}
    if getattr(args, "columns_file", None):
        from hybridev.core.fileio import read_table

        t = read_table(args.columns_file)
        if list(t.columns[:2]) != ["old", "new"]:
            raise ValueError(f"--columns-file={args.columns_file!r} must have the columns "
                             f"old,new; got {list(t.columns)}")
        mapping.update(zip(t["old"].astype(str).str.strip(), t["new"].astype(str).str.strip(),
                           strict=True))
    spec = getattr(args, "columns", None)
    if spec:
        for item in spec.split(","):
            old, sep, new = item.partition("=")
            old, new = old.strip(), new.strip()
            if not sep or not old or not new:
                raise ValueError(f"--columns item {item!r} must be OLD=NEW (e.g. "
                                 "mean_speed_kmh=avg_speed_kmh)")
            mapping[old] = new
    news = list(mapping.values())
    dup = sorted({n for n in news if news.count(n) > 1})
    if dup:
        raise ValueError(f"--columns maps several columns to {dup}; each new name once")
    return mapping


def apply_columns(table, mapping: dict[str, str], *, what: str, strict: bool = True):
    """Rename ``table``'s columns; ``strict``: every old name must exist."""
    if not mapping:
        return table
    present = {o: n for o, n in mapping.items() if o in table.columns}
    if strict:
        missing = [o for o in mapping if o not in table.columns]
        if missing:
            raise ValueError(f"--columns: {what} has no column(s) {missing}; its columns: "
                             f"{list(table.columns)}")
    clash = [n for o, n in present.items() if n in table.columns and n not in present]
    if clash:
        raise ValueError(f"--columns: {what} already has column(s) {clash}; map them away "
                         "first (e.g. old_name=unused_name) or pick another source column")
    return table.rename(columns=present)


def fill_soc_initial(table, soc_initial: float | None):
    """Fill a missing or empty ``soc_initial`` with ``--soc-initial``."""
    if soc_initial is None:
        return table
    if not 0.0 <= soc_initial <= 1.0:
        raise ValueError(f"--soc-initial={soc_initial!r} is outside the allowed range [0, 1]")
    if "soc_initial" not in table.columns:
        return table.assign(soc_initial=soc_initial)
    return table.assign(soc_initial=table["soc_initial"].fillna(soc_initial))


def hint_missing_soc(exc: ValueError) -> ValueError:
    """Add what to do to a 'missing soc_initial' error."""
    msg = str(exc)
    head = msg.split("; required:")[0]  # the missing columns, not the required list
    if "soc_initial" in head and "missing" in head:
        return ValueError(msg + "; a logger without SoC: give --soc-initial S (e.g. 0.9), "
                          "and map your energy column to energy_kwh with --columns")
    return exc


def read_trips(path, args: argparse.Namespace, *, measured: bool, vehicle=None,
               strict: bool | None = None, whole: bool = False):
    """Read a trip table with the shared options: (table, traces or None, rejected or None).

    ``measured``: a measured-trip table (validated by
    :func:`hybridev.data.logs.measured_from_frames`, rejected rows reported);
    else a trip table to predict on (summaries derived from the traces).
    ``strict`` (default ``measured``): every ``--columns`` source must exist.
    ``whole`` (measured only): return the whole
    :class:`~hybridev.data.logs.MeasuredTrips` (its elevation and derived-column
    reports too, for :func:`print_data_quality`) instead of the three parts.
    """
    from hybridev.core.fileio import read_table

    mapping = column_mapping(args)
    strict = measured if strict is None else strict
    ts_path = getattr(args, "timeseries", None)
    # with traces, ids are matched across two files: read them as text ('007' stays '007')
    ids = () if ts_path is None else tuple({"trip_id", *(o for o, n in mapping.items()
                                                          if n == "trip_id")})
    raw = read_table(path, text_columns=ids)
    ts = None
    if ts_path is not None:
        raw_ts = read_table(ts_path, text_columns=ids)
        missing = [o for o in mapping if o not in raw.columns and o not in raw_ts.columns]
        if strict and missing:
            raise ValueError(f"--columns: neither {path} nor {ts_path} has column(s) {missing}; "
                             f"their columns: {list(raw.columns)} and {list(raw_ts.columns)}")
        ts = apply_columns(raw_ts, mapping, what=str(ts_path), strict=False)
        from hybridev.cli.traces import precheck_traces

        ts = precheck_traces(ts)  # sort out-of-order samples; flag jumps and conflicts
        strict = False  # checked above over both files
    table = apply_columns(raw, mapping, what=str(path), strict=strict)
    if ts is None or "soc" not in ts.columns:  # a logged soc comes first
        table = fill_soc_initial(table, getattr(args, "soc_initial", None))
    try:
        if measured:
            from hybridev.cli.traces import miles_hint
            from hybridev.data.logs import measured_from_frames

            m = measured_from_frames(table, ts, vehicle)
            rejected = m.rejected
            if rejected is not None and len(rejected):
                rejected = rejected.assign(reason=rejected["reason"].map(miles_hint))
            if whole:
                import dataclasses

                return dataclasses.replace(m, rejected=rejected)
            return m.trips, m.traces, rejected
        if ts is None:
            return table, None, None
        from hybridev.data.logs import _derive_from_traces, harmonise_trip_ids, match_traces
        from hybridev.data.timeseries import validate_timeseries

        if "trip_id" not in table.columns:
            raise ValueError("trips need a 'trip_id' column to be matched with a time series")
        table, ts = harmonise_trip_ids(table, ts)
        traces, rejected = validate_timeseries(ts)
        match_traces(table, traces, warn=False)
        _check_against_traces(table, traces, path)  # as fit and calibrate do
        if len(rejected):  # the trips stay: predicted on a synthesised trace instead
            rejected = rejected.assign(reason=rejected["reason"].astype(str)
                                       + "; the trip is predicted on a synthesised trace")
        table = fill_soc_initial(_derive_from_traces(table, traces),
                                 getattr(args, "soc_initial", None))
        match_traces(table, traces, what="trips to predict")
        return table, traces, rejected
    except ValueError as exc:
        raise hint_missing_soc(exc) from exc


def _check_against_traces(table, traces, path) -> None:
    """A trip row whose distance or mean speed disagrees with its trace is an error."""
    from hybridev.cli.traces import miles_hint
    from hybridev.data.logs import _trace_mismatch

    parts = _trace_mismatch(table, traces)
    if not parts:
        return
    import pandas as pd

    bad = pd.concat(parts, ignore_index=True)
    r = bad.iloc[0]
    raise ValueError(f"{len(bad)} trip(s) of {path} disagree with their logged trace (fit and "
                     f"calibrate reject such rows; first: row {r['row']}, trip_id="
                     f"{r['trip_id']!r}: {miles_hint(r['reason'])}); fix the table or the "
                     "trace, or leave the column out to derive it from the trace")


def report_rejected(command: str, source: str, rejected, limit: int = 10) -> None:
    """Print rejected rows (source, row, reason) to stderr."""
    import sys

    if rejected is None or len(rejected) == 0:
        return
    print(f"hybridev {command}: rejected {len(rejected)} row(s)/trace(s) of {source}:",
          file=sys.stderr)
    for r in rejected.head(limit).itertuples():
        row = getattr(r, "row", None)
        where = (f"row {row}" if row is not None and not (isinstance(row, float) and row != row)
                 else f"trip_id={getattr(r, 'trip_id', None)!r}")
        print(f"  {getattr(r, 'source', 'trips')} {where}: {r.reason}", file=sys.stderr)
    if len(rejected) > limit:
        print(f"  ... and {len(rejected) - limit} more", file=sys.stderr)


def print_data_quality(measured) -> None:
    """Print the short data-quality block (:func:`hybridev.data.quality.data_quality`) of a
    :class:`~hybridev.data.logs.MeasuredTrips` or a validated table, before the fit."""
    import pandas as pd

    from hybridev.data.logs import MeasuredTrips
    from hybridev.data.quality import data_quality

    if isinstance(measured, pd.DataFrame):  # a table read without traces: nothing rejected
        measured = MeasuredTrips(measured, None, pd.DataFrame(columns=[
            "source", "row", "trip_id", "field", "value", "reason"]))
    print(data_quality(measured).text(), flush=True)
