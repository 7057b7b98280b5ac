"""The Python package against the command line: the same tables, the same
parameters, the same places in errors."""

import math
import pathlib

import polars as pl
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import robotid
from conftest import robotid as cli

CRC = b"robotid.content_crc32"


def largest_relative_difference(a: pa.Table, b: pa.Table) -> float:
    """Over values (scaled by the larger of |value| and its std: a value
    near zero is known only to its std) and stds."""
    assert a["name"].equals(b["name"])
    scale = pc.max_element_wise(pc.abs(b["value"]), b["std"])
    dv = pc.max(pc.divide(pc.abs(pc.subtract(a["value"], b["value"])), scale)).as_py()
    ds = pc.max(pc.divide(pc.abs(pc.subtract(a["std"], b["std"])), b["std"])).as_py()
    return max(dv, ds)


def same(a: pa.Table, b: pa.Table) -> bool:
    """Equal names, types and values, NaN equal to NaN (a variance not known)."""
    if a.schema.names != b.schema.names or a.num_rows != b.num_rows:
        return False
    for x, y in zip(a.columns, b.columns):
        if x.type != y.type:
            return False
        if pa.types.is_floating(x.type):
            if not pc.is_nan(x).equals(pc.is_nan(y)):
                return False
            x, y = pc.if_else(pc.is_nan(x), 0.0, x), pc.if_else(pc.is_nan(y), 0.0, y)
        if not x.equals(y):
            return False
    return True


def without_crc(schema: pa.Schema) -> dict:
    return {k: v for k, v in (schema.metadata or {}).items() if k != CRC}


@pytest.fixture(scope="module")
def kuka(examples):
    return examples / "pipelines" / "kuka_axis3.toml"


@pytest.fixture(scope="module")
def kuka_run(kuka, tmp_path_factory):
    out = tmp_path_factory.mktemp("kuka")
    cli("run", kuka, "--out", out)
    return out


def every_table(kuka, kuka_run, tmp_path):
    """Every table kind robotid writes, as the package gives it, with the
    file the command line wrote for it."""
    p = robotid.Pipeline.from_path(kuka)
    (rec,) = p.recordings
    name = pathlib.Path(rec).stem
    for kind, table in p.run_recording(rec).items():
        yield kind, table, kuka_run / name / f"{kind}.parquet"
    yield "parameters", robotid.solve([p.summarize(r) for r in p.recordings], p), kuka_run / "parameters.parquet"
    validation = kuka.parent / "validation.toml"
    v = robotid.Pipeline.from_path(validation)
    vout = tmp_path / "validation"
    cli("run", validation, "--out", vout)
    for rec in v.recordings:
        name = pathlib.Path(rec).stem
        for kind, table in v.run_recording(rec).items():
            yield kind, table, vout / name / f"{kind}.parquet"


def test_every_table_kind_equals_the_command_lines_and_round_trips(kuka, kuka_run, tmp_path):
    kinds = set()
    for kind, table, written in every_table(kuka, kuka_run, tmp_path):
        kinds.add(kind)
        cli_table = pq.read_table(written)
        # The same values, units and provenance as the file `robotid run` wrote.
        assert same(table, cli_table), kind
        assert table.schema.equals(cli_table.schema.with_metadata(without_crc(cli_table.schema)), check_metadata=True), kind
        assert without_crc(table.schema) == without_crc(cli_table.schema), kind
        assert table.schema.metadata[b"robotid.table"].decode() == kind
        floats = [f for f in table.schema if pa.types.is_floating(f.type)]
        assert floats and all(f.metadata and b"unit" in f.metadata for f in floats), kind
        # pyarrow → Parquet → pyarrow keeps every unit and key.
        path = tmp_path / f"{kind}.parquet"
        pq.write_table(table, path)
        back = pq.read_table(path)
        assert same(back, table) and back.schema.equals(table.schema, check_metadata=True), kind
        # polars: the same values; the file-level keys through its Parquet
        # reader (polars frames have no per-column metadata).
        frame = pl.from_arrow(table)
        assert frame.shape == (table.num_rows, table.num_columns)
        names = [f.name for f in floats]
        assert same(pa.table({n: frame[n].to_arrow() for n in names}), table.select(names)), kind
        keys = pl.read_parquet_metadata(written)
        assert keys["robotid.table"] == kind and keys["robotid.config_sha256"]
    assert kinds == {"period_mean", "noise", "kinematics", "regressor", "r_factor", "parameters", "raw_samples"}, kinds


def test_bytes_and_paths_give_the_same_tables(kuka):
    p = robotid.Pipeline.from_path(kuka)
    (rec,) = p.recordings
    from_path = p.run_recording(rec)
    from_bytes = p.run_recording(pathlib.Path(rec).read_bytes(), name=pathlib.Path(rec).name)
    assert from_path.keys() == from_bytes.keys()
    for k in from_path:
        assert from_path[k]["time" if "time" in from_path[k].column_names else 0].equals(
            from_bytes[k]["time" if "time" in from_bytes[k].column_names else 0]
        )


def test_pipeline_from_toml_resolves_paths_against_base_dir(kuka):
    p = robotid.Pipeline.from_toml(kuka.read_text(), kuka.parent)
    assert p.config_sha256 == robotid.Pipeline.from_path(kuka).config_sha256
    assert len(p.recordings) == 1


def test_errors_carry_their_place(kuka, tmp_path):
    p = robotid.Pipeline.from_path(kuka)
    with pytest.raises(robotid.RobotidError) as e:
        p.run_recording(b"time,q\n0,1\n", name="bad.csv")
    assert e.value.file == "<bytes bad>" and e.value.channel == "q_a3", str(e.value)
    assert "missing column" in str(e.value)
    # A sample at fault is named: time stamps that go back.
    arm3 = robotid.Pipeline.from_path(kuka.parent / "arm3.toml")
    rec = tmp_path / "back.csv"
    header = "time," + ",".join(f"q_j{j},current_j{j}" for j in (1, 2, 3)) + "\n"
    rec.write_text(header + "".join(f"{t}" + ",0.0" * 6 + "\n" for t in [0.0, 0.1, 0.05, 0.2]))
    with pytest.raises(robotid.RobotidError) as e:
        arm3.run_recording(rec)
    assert e.value.file == str(rec) and e.value.sample is not None, str(e.value)
    # An error in a stage names it: 3 s of a 10 s period, given as bytes.
    short = header + "".join(
        f"{0.01 * k}" + "".join(f",{0.3 * math.sin(0.01 * k * j)},0.1" for j in (1, 2, 3)) + "\n" for k in range(300)
    )
    with pytest.raises(robotid.RobotidError) as e:
        arm3.run_recording(short.encode(), name="short.csv")
    assert (e.value.file, e.value.stage, e.value.channel) == ("<bytes short>", "align", "time"), str(e.value)
    assert "stage `align`" in str(e.value) and "less than one full period" in str(e.value)
    with pytest.raises(robotid.RobotidError) as e:
        robotid.Pipeline.from_toml("version = 1\n[[stage]]\nkind = 'nonsense'\n", tmp_path)
    assert e.value.file.endswith("pipeline.toml") and "missing field `source`" in str(e.value)
    with pytest.raises(robotid.RobotidError) as e:
        robotid.merge([])
    assert "none given" in str(e.value)


def test_summaries_solve_to_the_command_lines_parameters(fleet, tmp_path):
    pipeline = fleet["pipelines"]["arm3"]
    out = tmp_path / "arm3"
    cli("run", pipeline, "--out", out)
    expected = pq.read_table(out / "parameters.parquet")
    p = robotid.Pipeline.from_path(pipeline)
    parts = [p.summarize(r) for r in p.recordings]
    assert all(s.num_rows == 1 and s.schema.metadata[b"robotid.table"] == b"summary" for s in parts)
    in_order = robotid.solve(parts, p)
    assert in_order["value"].equals(expected["value"]) and in_order["std"].equals(expected["std"])
    # Merged in uneven groups, in another order.
    groups = [robotid.merge(parts[i::3][::-1]) for i in range(3)]
    regrouped = robotid.solve(robotid.merge(groups[::-1]), p)
    assert largest_relative_difference(regrouped, expected) < 1e-10
