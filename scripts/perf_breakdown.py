"""Where `robotid run` spends its time, by stage, from `perf script` output
(scripts/profile-run.sh): each sample goes to the stage whose code is on
its stack, the innermost frame that names one (rayon worker stacks carry
the stage's closures). usage: perf_breakdown.py PERF_SCRIPT.txt"""
import collections, sys
buckets = [
 ('read (MCAP: zstd chunks, CDR JointState)', ['read_mcap', 'stage::read::', 'start_chain', 'mcap::']),
 ('align', ['stage::align::', '5align']),
 ('inverse_filter', ['inverse_filter', 'spectral_filter']),
 ('average', ['stage::average::']),
 ('noise (spectra, normality tests)', ['stage::noise::', '5noise']),
 ('differentiate (Fourier fit)', ['differentiate']),
 ('regressor (batched kernel, Gram, torque check)', ['stage::regressor::', 'regressor_rows', 'base_regressor::BaseRegressor::matrix', 'batch::']),
 ('estimate (R factor, solve, covariance)', ['stage::estimate::', 'summary::Summary', 'Reducer', 'estimation::']),
 ('write (tables, Parquet zstd)', ['formats::parquet', 'write_parquet', 'tables_of', 'take_tables', 'write_atomic', 'into_record_batch', 'parquet::']),
 ('build (robot file, URDF, base parameters)', ['Pipeline::build', 'base_parameters', 'BaseRegressor::new', 'load_robot', 'urdf::', 'Pipeline5build', 'plan::']),
]
samples, cur = [], []
for line in open(sys.argv[1]):
    if not line.startswith('\t') and line.strip():
        samples.append(cur); cur = []
    elif line.strip():
        cur.append(line.strip().split(' ', 1)[-1])
samples.append(cur)
samples = [s for s in samples if s]
count = collections.Counter()
for s in samples:
    # A rayon worker with nothing to do yields its core: not time the run waits for.
    if any('sched_yield' in f or f.startswith('__schedule') for f in s[:8]):
        count['idle (rayon workers yielding)'] += 1
        continue
    hit = None
    for frame in s:  # innermost first
        for name, keys in buckets:
            if any(k in frame for k in keys):
                hit = name
                break
        if hit:
            break
    count[hit or 'other (process start and exit, stacks perf could not unwind)'] += 1
idle = count.pop('idle (rayon workers yielding)', 0)
busy = sum(count.values())
for k, v in count.most_common():
    print(f'{100 * v / busy:5.1f} %  {k}')
print(f'{busy} busy samples; {idle} more of idle rayon workers left out')
