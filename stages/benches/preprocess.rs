//! Each preprocessing stage on a synthetic 10-minute, 6-joint, 1 kHz
//! recording (600 k samples per channel); throughput in samples per second.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use robotid_stages::signal::{FilterFamily, FilterSpec, Spectra};
use robotid_stages::simulation::synthetic::synthetic_recording;
use robotid_stages::stage::align::{align, AlignConfig};
use robotid_stages::stage::average::average;
use robotid_stages::stage::differentiate::{differentiate, Differentiation};
use robotid_stages::stage::inverse_filter::{inverse_filter_periods, InverseFilterConfig};
use robotid_stages::stage::noise::noise;

fn stages(c: &mut Criterion) {
    let raw = synthetic_recording(6, 1000.0, 600.0, 10.0, 1);
    let samples = raw.len() as u64;
    let spectra = Spectra::new();
    let cfg = AlignConfig::default();
    let periods = align(&raw, &cfg, "bench").unwrap();
    let ifc = InverseFilterConfig {
        delay_s: None,
        filter: Some(FilterSpec {
            family: FilterFamily::Chebyshev1,
            order: 8,
            cutoff_hz: 100.0,
            ripple_db: Some(0.5),
        }),
        zpk: None,
        bandwidth_hz: 100.0,
    };
    // Built once per run, as the stage does.
    let response = ifc.response().unwrap();
    let (mean, _) = average(&periods);
    let h = [1, 2, 3, 4, 5];
    let mut g = c.benchmark_group("stages_6joints_600k");
    g.sample_size(10);
    g.throughput(Throughput::Elements(samples));
    g.bench_function("align", |b| b.iter(|| align(&raw, &cfg, "bench").unwrap()));
    g.bench_function("inverse_filter", |b| {
        b.iter_batched(
            || periods.clone(),
            |mut p| inverse_filter_periods(&mut p, &*response, ifc.bandwidth_hz, &spectra),
            criterion::BatchSize::LargeInput,
        )
    });
    g.bench_function("average", |b| b.iter(|| average(&periods)));
    g.bench_function("noise", |b| b.iter(|| noise(&periods, &mean, &h, None, &spectra)));
    g.bench_function("differentiate_fourier_fit", |b| {
        b.iter(|| differentiate(&mean, 10.0, Differentiation::FourierFit, &h, None, &spectra))
    });
    g.finish();
}

/// Writing a table with its content CRC-32 against the CRC alone: the
/// checksum's share of the write (600 k rows, 13 columns as a 6-joint
/// kinematics table).
fn parquet(c: &mut Criterion) {
    use arrow::array::{ArrayRef, Float64Array, RecordBatch};
    use robotid_stages::formats::parquet::{content_crc32, write_parquet};
    use std::sync::Arc;
    let rows = 600_000;
    let columns: Vec<(String, ArrayRef)> = (0..13)
        .map(|c| {
            let v = Float64Array::from_iter_values((0..rows).map(|i| ((i * (c + 3)) as f64 * 1e-3).sin()));
            (format!("c{c}"), Arc::new(v) as ArrayRef)
        })
        .collect();
    let batch = RecordBatch::try_from_iter(columns).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.parquet");
    let mut g = c.benchmark_group("parquet_600k_x13");
    g.sample_size(10);
    g.throughput(Throughput::Elements(rows as u64));
    g.bench_function("write_with_crc", |b| b.iter(|| write_parquet(&path, &batch).unwrap()));
    g.bench_function("plain_arrow_writer", |b| b.iter(|| plain_write(&path, &batch)));
    g.bench_function("crc_alone", |b| b.iter(|| content_crc32(&batch)));
    g.finish();

    // A regressor table's shape: 30 000 rows (6 joints × 5000 samples of
    // one period), 60 parameter columns and the torque.
    let rows = 30_000;
    let columns: Vec<(String, ArrayRef)> = (0..61)
        .map(|c| {
            let v = Float64Array::from_iter_values(
                (0..rows).map(|i| ((i * (c + 3)) as f64 * 1e-3).sin() * (1.0 + c as f64)),
            );
            (format!("c{c}"), Arc::new(v) as ArrayRef)
        })
        .collect();
    let batch = RecordBatch::try_from_iter(columns).unwrap();
    let mut g = c.benchmark_group("parquet_30k_x61");
    g.sample_size(20);
    g.throughput(Throughput::Elements(rows as u64));
    g.bench_function("write_with_crc", |b| b.iter(|| write_parquet(&path, &batch).unwrap()));
    g.bench_function("plain_arrow_writer", |b| b.iter(|| plain_write(&path, &batch)));
    g.finish();
}

/// The comparison: the same table through arrow-rs's `ArrowWriter` as it
/// comes (one thread, the Arrow schema in the file), with robotid's
/// compression (zstd level 1, no dictionaries for numbers), no checksum,
/// not atomic.
fn plain_write(path: &std::path::Path, batch: &arrow::array::RecordBatch) {
    use parquet::basic::{Compression, ZstdLevel};
    let props = parquet::file::properties::WriterProperties::builder()
        .set_compression(Compression::ZSTD(ZstdLevel::try_new(1).unwrap()))
        .set_dictionary_enabled(false)
        .build();
    let file = std::fs::File::create(path).unwrap();
    let mut w = parquet::arrow::ArrowWriter::try_new(file, batch.schema(), Some(props)).unwrap();
    w.write(batch).unwrap();
    w.close().unwrap();
}

criterion_group!(benches, stages, parquet);
criterion_main!(benches);
