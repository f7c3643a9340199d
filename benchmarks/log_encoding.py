"""Log encoding benchmark (issue 34, item 1): the run log's row encodings against each other, in one process.

  pack      the payloads of a block of rows packed by numpy, no MCAP: CDR as format 7 wrote it (six payloads a
            row, one per row topic: the 4-byte header, then float64 t and one float64 per field) and as format 8
            writes it (one /row payload a row: the header, t, then every topic's fields), protobuf with one named
            double field per value (each a tag byte and 8 bytes: what Foxglove would plot by name), protobuf with
            one packed repeated double (tag, length, 8 bytes a value: plotted by index only); µs per payload and
            zstd bytes per row
  write     Recorder.write_rows of synthetic heave rows (order 2, 3 parameters, 1000-step blocks logged at
            100 Hz, dt = 1 ms) with log.encoding json (format 6: JSON text, six messages a row, the same code as
            before format 7) and cdr (format 8: one message a row): µs per row and per message
  size      real heave runs at 100 Hz with each encoding: heave_drift of 2 s and 20 s (the 20 s file over 20 s,
            and the difference over 18 s, without the header) and heave_tracking of 2 s and 12 s (the difference
            over 10 s): log bytes per simulated second, and the message index's share (16 bytes a message,
            uncompressed, needed by @mcap/core and Foxglove)
  steps     per physics step of heave_tracking (20 000 steps, RK4, 1 ms), interleaved in each repetition: bare
            mj_step (speed.py's a), the closed loop without a log (its b: the law's own cost), the closed loop
            logged at 100 Hz with log.encoding json (speed.py's c as it was before format 7: the JSON writer's
            code is unchanged) and with cdr; the ratios to a

Every timing is the median of --reps repetitions, with [min, max].
Usage: python benchmarks/log_encoding.py [--reps 7] [--blocks 20]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

import numpy as np
import zstandard

from adaptive_mj.log.record import CDR_HEADER, LogHeader, Recorder, row_fields
from adaptive_mj.setup import scenario as sc
from adaptive_mj.runs.runner import execute

REPO = Path(__file__).resolve().parents[1]
NAMES = ("d", "b", "c")
DT, BLOCK, EVERY = 0.001, 1000, 10


def med(xs):
    return {"median": statistics.median(xs), "min": min(xs), "max": max(xs)}


def synthetic(n: int, seed: int = 0) -> dict:
    """n physics steps of plausible heave rows, full-precision floats (as tests/test_record.py)."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) * DT
    x = np.column_stack([np.sin(t + j) + 1e-3 * rng.standard_normal(n) for j in range(2)])
    ref = np.column_stack([np.sin(t + j) for j in range(3)])
    s = 1e-2 * rng.standard_normal(n)
    theta_hat = np.column_stack([1 + 0.1 * np.sin(t * (j + 1)) + 1e-4 * rng.standard_normal(n) for j in range(3)])
    return dict(t=t, x=x, u=10 * np.cos(t) + rng.standard_normal(n), s=s, ref=ref, theta_hat=theta_hat,
                theta=np.tile([37.0, 60.0, 1.0], (n, 1)), V=0.5 * s**2 + rng.random(n))


def blocks_of(rows: dict) -> tuple[np.ndarray, list[np.ndarray]]:
    """The kept rows' t and the six topics' columns (as Recorder.write_rows forms them)."""
    keep = slice(0, None, EVERY)
    x, ref = rows["x"][keep], rows["ref"][keep]
    control = np.column_stack([rows["u"][keep], rows["s"][keep], ref[:, 0] - x[:, 0]])
    return rows["t"][keep], [x, ref, control, rows["theta_hat"][keep], rows["theta"][keep], rows["V"][keep, None]]


def pack_cdr_row(tk, blocks) -> list[bytes]:
    """Format 8: one payload a row, the CDR header, t, then every topic's columns."""
    rec = np.empty(len(tk), dtype=[("h", "u1", (4,)), ("v", "<f8", (1 + sum(b.shape[1] for b in blocks),))])
    rec["h"] = np.frombuffer(CDR_HEADER, np.uint8)
    rec["v"] = np.hstack([tk[:, None], *blocks])
    return [rec.tobytes()]


def pack_cdr(tk, blocks) -> list[bytes]:
    """Format 7: six payloads a row, one per topic, each the CDR header, t and the topic's columns."""
    out = []
    for b in blocks:
        rec = np.empty(len(tk), dtype=[("h", "u1", (4,)), ("v", "<f8", (1 + b.shape[1],))])
        rec["h"] = np.frombuffer(CDR_HEADER, np.uint8)
        rec["v"][:, 0], rec["v"][:, 1:] = tk, b
        out.append(rec.tobytes())
    return out


def pack_proto_named(tk, blocks) -> list[bytes]:
    """proto3 `double f1 = 1; double f2 = 2; ...`, every field written (tag (k << 3) | 1, then 8 bytes)."""
    out = []
    for b in blocks:
        width = 1 + b.shape[1]
        rec = np.empty(len(tk), dtype=[(f"f{k}", [("tag", "u1"), ("v", "<f8")]) for k in range(width)])
        for k in range(width):
            rec[f"f{k}"]["tag"] = ((k + 1) << 3) | 1
            rec[f"f{k}"]["v"] = tk if k == 0 else b[:, k - 1]
        out.append(rec.tobytes())
    return out


def pack_proto_packed(tk, blocks) -> list[bytes]:
    """proto3 `repeated double values = 1;` packed: tag 0x0a, varint length (< 128 here), 8 bytes a value."""
    out = []
    for b in blocks:
        width = 1 + b.shape[1]
        rec = np.empty(len(tk), dtype=[("tag", "u1"), ("len", "u1"), ("v", "<f8", (width,))])
        rec["tag"], rec["len"] = 0x0A, 8 * width
        rec["v"][:, 0], rec["v"][:, 1:] = tk, b
        out.append(rec.tobytes())
    return out


def bench_pack(reps: int) -> dict:
    tk, blocks = blocks_of(synthetic(BLOCK * 20))
    zstd = zstandard.ZstdCompressor(level=3)
    out = {}
    for name, pack in (("cdr_format8_row", pack_cdr_row), ("cdr_format7_topics", pack_cdr),
                       ("protobuf_named_doubles", pack_proto_named), ("protobuf_packed_repeated", pack_proto_packed)):
        messages = len(tk) * (1 if pack is pack_cdr_row else len(blocks))
        times = []
        for _ in range(reps):
            t0 = time.perf_counter()
            parts = pack(tk, blocks)
            times.append((time.perf_counter() - t0) / messages * 1e6)
        raw = sum(map(len, parts))
        # the payloads of one row interleaved, as they lie in a chunk (heads left out)
        width = [len(p) // len(tk) for p in parts]
        rows = b"".join(b"".join(p[i * w:(i + 1) * w] for p, w in zip(parts, width, strict=True))
                        for i in range(len(tk)))
        out[name] = {"us_per_message": med(times), "bytes_per_row": raw / len(tk),
                     "zstd_bytes_per_row": len(zstd.compress(rows)) / len(tk)}
    return out


def header(encoding: str) -> LogHeader:
    return LogHeader(scenario_name="bench", scenario_text="", scenario_source="", overrides=(), seed=0,
                     log_rate_hz=100.0, dt=DT, order=2, param_names=NAMES, model_xml=None, model_source=None,
                     encoding=encoding)


def bench_write(reps: int, n_blocks: int) -> dict:
    rows = synthetic(BLOCK * n_blocks)
    per_row = {"json": len(row_fields(2, NAMES)), "cdr": 1}  # messages a row: format 6 six, format 8 one
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        times: dict[str, list[float]] = {"json": [], "cdr": []}
        for _ in range(reps):
            for encoding in times:  # interleaved: the machine's load falls on both alike
                rec = Recorder(Path(tmp) / f"{encoding}.mcap", header(encoding))
                t0 = time.perf_counter()
                for k0 in range(0, BLOCK * n_blocks, BLOCK):
                    sl = slice(k0, k0 + BLOCK)
                    rec.write_rows(k0, rows["t"][sl], rows["x"][sl], rows["u"][sl], rows["s"][sl], rows["ref"][sl],
                                   rows["theta_hat"][sl], rows["theta"][sl], rows["V"][sl])
                times[encoding].append((time.perf_counter() - t0) / rec.rows_written * 1e6)
                rec.close("ok", "", {})
        for encoding, ts in times.items():
            out[encoding] = {"us_per_row": med(ts), "us_per_message": med([t / per_row[encoding] for t in ts])}
    return out


def bench_size() -> dict:
    """{scenario: {encoding: sizes}}: heave_drift 2 s and 20 s, heave_tracking 2 s and 12 s, at 100 Hz."""
    from mcap.stream_reader import StreamReader

    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        for name, long in (("heave_drift", 20), ("heave_tracking", 12)):
            for encoding in ("json", "cdr"):
                sizes, index = {}, {}
                for seconds in (2, long):
                    scn = sc.load(REPO / "scenarios" / f"{name}.toml",
                                  overrides=[f"simulation.duration={seconds}", "log.rate_hz=100",
                                             f"log.encoding={encoding!r}"])
                    path = Path(tmp) / f"{name}_{encoding}{seconds}.mcap"
                    execute(scn, log_path=path)
                    sizes[seconds] = path.stat().st_size
                    with open(path, "rb") as f:
                        index[seconds] = sum(15 + 16 * len(r.records) for r in StreamReader(f).records
                                             if type(r).__name__ == "MessageIndex")
                span = long - 2
                out.setdefault(name, {})[encoding] = {
                    "seconds": long, "bytes_per_sim_second": (sizes[long] - sizes[2]) / span,
                    "whole_file_bytes_per_sim_second": sizes[long] / long,
                    "message_index_bytes_per_sim_second": (index[long] - index[2]) / span,
                    "file_bytes": sizes[long]}
    return out


def bench_steps(reps: int, steps: int) -> dict:
    import importlib.util

    spec = importlib.util.spec_from_file_location("speed", Path(__file__).with_name("speed.py"))
    assert spec is not None and spec.loader is not None
    speed = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(speed)
    name = "heave_tracking"
    speed.loop(name, 500, True)  # compile the native callback once (numba), outside the timing
    rows: dict[str, list[float]] = {"a_bare": [], "b_no_log": [], "c_json": [], "c_cdr": []}
    for _ in range(reps):
        rows["a_bare"].append(speed.bare(name, steps))
        rows["b_no_log"].append(speed.loop(name, steps, True))
        rows["c_json"].append(speed.logged(name, steps, None, ("log.encoding='json'",))[0])
        rows["c_cdr"].append(speed.logged(name, steps, None, ("log.encoding='cdr'",))[0])
    out = {k: med(v) for k, v in rows.items()}
    a = out["a_bare"]["median"]
    # the ratio of each repetition's own figures, too: the load on a shared machine moves them together
    out["ratios"] = {"b/a": out["b_no_log"]["median"] / a,
                     "c_json/a": out["c_json"]["median"] / a, "c_cdr/a": out["c_cdr"]["median"] / a,
                     "c_json/a per rep": med([c / b for c, b in zip(rows["c_json"], rows["a_bare"], strict=True)]),
                     "c_cdr/a per rep": med([c / b for c, b in zip(rows["c_cdr"], rows["a_bare"], strict=True)])}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--reps", type=int, default=7)
    ap.add_argument("--blocks", type=int, default=20, help="1000-step blocks per write timing")
    ap.add_argument("--steps", type=int, default=20000, help="physics steps per figure of the steps section")
    ap.add_argument("--no-steps", action="store_true", help="skip the per-step section")
    args = ap.parse_args()
    pack = bench_pack(args.reps)
    print(f"pack (a block of {BLOCK * 20 // EVERY} heave rows, 6 topics; median [min, max] of {args.reps}):")
    for name, r in pack.items():
        m = r["us_per_message"]
        print(f"  {name:26s} {m['median']:6.3f} µs/payload [{m['min']:.3f}, {m['max']:.3f}]  "
              f"{r['bytes_per_row']:.0f} B/row raw, {r['zstd_bytes_per_row']:.1f} B/row zstd")
    write = bench_write(args.reps, args.blocks)
    print(f"write (Recorder.write_rows, {args.blocks} blocks of 1000 steps at 100 Hz; json 6 messages a row, "
          "cdr 1):")
    for name, r in write.items():
        m, row = r["us_per_message"], r["us_per_row"]
        print(f"  {name:5s} {row['median']:6.2f} µs/row [{row['min']:.2f}, {row['max']:.2f}], "
              f"{m['median']:6.3f} µs/message")
    print(f"  json/cdr: {write['json']['us_per_row']['median'] / write['cdr']['us_per_row']['median']:.1f}x")
    size = bench_size()
    for scenario, by_encoding in size.items():
        long = by_encoding["json"]["seconds"]
        print(f"size ({scenario} at 100 Hz, {long} s run minus 2 s run, per simulated second):")
        for name, r in by_encoding.items():
            print(f"  {name:5s} {r['bytes_per_sim_second'] / 1000:5.2f} kB/s (the whole {long} s file: "
                  f"{r['whole_file_bytes_per_sim_second'] / 1000:.2f} kB/s, {r['file_bytes']} B), of it the message "
                  f"index {r['message_index_bytes_per_sim_second'] / 1000:.2f} kB/s")
        ratio = by_encoding["cdr"]["bytes_per_sim_second"] / by_encoding["json"]["bytes_per_sim_second"]
        print(f"  cdr/json: {ratio:.2f}")
    if args.no_steps:
        return
    steps = bench_steps(args.reps, args.steps)
    print(f"steps (heave_tracking, {args.steps} steps, logged at 100 Hz; median [min, max] of {args.reps}, "
          "interleaved):")
    for key in ("a_bare", "b_no_log", "c_json", "c_cdr"):
        m = steps[key]
        print(f"  {key:8s} {m['median']:7.2f} µs/step [{m['min']:.2f}, {m['max']:.2f}]")
    r = steps["ratios"]
    rj, rc = r["c_json/a per rep"], r["c_cdr/a per rep"]
    print(f"  b/a {r['b/a']:.2f} (no log); c/a: json {r['c_json/a']:.2f}, cdr {r['c_cdr/a']:.2f}; per repetition: json "
          f"{rj['median']:.2f} [{rj['min']:.2f}, {rj['max']:.2f}], cdr {rc['median']:.2f} [{rc['min']:.2f}, "
          f"{rc['max']:.2f}]")


if __name__ == "__main__":
    main()
