#!/usr/bin/env bash
# robotid's dynamics kernels against Pinocchio's C++, side by side in one
# run, on example-robot-data's UR5 and Panda (fingers locked) and the same
# 1024 states: the regressor (computeJointTorqueRegressor) and RNEA, per
# sample, single-threaded. Pinocchio comes from the pip `pin` wheel of the
# test venv (its headers and libraries, plus cmeel-eigen for Eigen's
# headers, cmeel-urdfdom-headers for the URDF parser's); the small C++
# program below is compiled against them with -O3, Pinocchio's algorithms
# instantiated in it (header-only). robotid's side is `cargo bench --bench
# kernels`; both are baseline x86-64 builds (SSE2, no -march=native).
#   bash scripts/bench-pinocchio.sh [--quick]
set -euo pipefail
cd "$(dirname "$0")/.."
venv=$(bash scripts/venv.sh)
"$venv/bin/pip" install --quiet --disable-pip-version-check cmeel-eigen==3.4.1 cmeel-urdfdom-headers==3.0.0 >&2
prefix=$(realpath "$("$venv/bin/python" -c "import sysconfig; print(sysconfig.get_paths()['purelib'])")/cmeel.prefix")
robots="$prefix/share/example-robot-data/robots"
urdfs="ur5=$robots/ur_description/urdf/ur5_robot.urdf,panda=$robots/panda_description/urdf/panda.urdf"

work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
cat > "$work/bench.cpp" <<'EOF'
// Per-sample time of Pinocchio's regressor and RNEA on the states
// robotid's kernels bench draws (the same LCG); every joint that is not
// revolute (the Panda's fingers) locked, as robotid's URDF reader does.
#include <pinocchio/algorithm/model.hpp>
#include <pinocchio/algorithm/regressor.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/parsers/urdf.hpp>
#include <chrono>
#include <cstdint>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

namespace pin = pinocchio;

static uint64_t x = 1;
static double draw(double scale) {
  x = x * 6364136223846793005ULL + 1442695040888963407ULL;
  return scale * (double(x >> 11) / double(1ULL << 53) * 2.0 - 1.0);
}

template <class F> static double ns_per_sample(size_t samples, F f) {
  using clock = std::chrono::steady_clock;
  for (int w = 0; w < 20; ++w) f();  // warm up
  double best = 1e300;
  for (int r = 0; r < 30; ++r) {  // best of 30 runs of every sample
    auto t0 = clock::now();
    f();
    double ns = std::chrono::duration<double, std::nano>(clock::now() - t0).count();
    best = std::min(best, ns / samples);
  }
  return best;
}

int main(int argc, char** argv) {
  std::string list = argv[1];
  std::stringstream ss(list);
  std::string entry;
  while (std::getline(ss, entry, ',')) {
    auto eq = entry.find('=');
    std::string name = entry.substr(0, eq), path = entry.substr(eq + 1);
    pin::Model full;
    pin::urdf::buildModel(path, full);
    std::vector<pin::JointIndex> locked;
    for (pin::JointIndex j = 1; j < (pin::JointIndex)full.njoints; ++j)
      if (full.joints[j].shortname().rfind("JointModelR", 0) != 0) locked.push_back(j);  // not revolute
    pin::Model model = pin::buildReducedModel(full, locked, pin::neutral(full));
    pin::Data data(model);
    const size_t samples = 1024;
    std::vector<Eigen::VectorXd> q, v, a;
    for (size_t k = 0; k < samples; ++k) {
      Eigen::VectorXd qk(model.nv), vk(model.nv), ak(model.nv);
      for (int j = 0; j < model.nv; ++j) qk[j] = draw(3.0);
      for (int j = 0; j < model.nv; ++j) vk[j] = draw(2.0);
      for (int j = 0; j < model.nv; ++j) ak[j] = draw(8.0);
      q.push_back(qk), v.push_back(vk), a.push_back(ak);
    }
    double sink = 0;
    double reg = ns_per_sample(samples, [&] {
      for (size_t k = 0; k < samples; ++k)
        sink += pin::computeJointTorqueRegressor(model, data, q[k], v[k], a[k])(0, 0);
    });
    double tau = ns_per_sample(samples, [&] {
      for (size_t k = 0; k < samples; ++k) sink += pin::rnea(model, data, q[k], v[k], a[k])[0];
    });
    std::cout << name << " " << model.nv << " " << reg << " " << tau << "\n";
    std::cerr << "checksum " << sink << "\n";  // keeps the calls from being optimised away
  }
}
EOF
echo "compiling the Pinocchio benchmark against $prefix" >&2
# The definitions Pinocchio's CMake config exports. No -march=native: the
# wheel's libraries are built for baseline x86-64, and Eigen's alignment
# under AVX changes the layout of the Model they hand over (a crash).
g++ -std=c++17 -O3 -DNDEBUG -w \
  -DBOOST_MPL_LIMIT_LIST_SIZE=30 -DBOOST_MPL_LIMIT_VECTOR_SIZE=30 -DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS \
  -DBOOST_FUSION_INVOKE_MAX_ARITY=12 -DPINOCCHIO_WITH_URDFDOM -DPINOCCHIO_URDFDOM_HEADERS_MAJOR_VERSION=3 \
  -DPINOCCHIO_URDFDOM_HEADERS_MINOR_VERSION=0 -DPINOCCHIO_URDFDOM_HEADERS_PATCH_VERSION=0 \
  -I"$prefix/include" -I"$prefix/include/urdfdom_headers" -I"$prefix/include/eigen3" \
  "$work/bench.cpp" -o "$work/bench" -L"$prefix/lib" -Wl,-rpath,"$prefix/lib" \
  -lpinocchio_parsers -lpinocchio_default -lurdfdom_model -lboost_filesystem -lboost_serialization
"$work/bench" "$urdfs" > "$work/pinocchio.txt" 2> /dev/null

quick=()
[ "${1:-}" = "--quick" ] && quick=(--warm-up-time 1 --measurement-time 2)
ROBOTID_KERNEL_URDFS="$urdfs" cargo bench -q -p robotid-stages --bench kernels -- "${quick[@]}" 2>/dev/null \
  | tee "$work/robotid.txt" | grep -E "^kernels_|time:" || true

# Criterion prints "kernels_<robot>/<kernel>/<variant>" and then
# "time: [low mid high]"; the middle value is per 1024 samples.
"$venv/bin/python" - "$work/pinocchio.txt" "$work/robotid.txt" <<'EOF'
import re, sys
pin = {}
for line in open(sys.argv[1]):
    name, dof, reg, tau = line.split()[:4]
    pin[name] = (int(dof), float(reg), float(tau))
unit = {"ps": 1e-3, "ns": 1.0, "µs": 1e3, "us": 1e3, "ms": 1e6, "s": 1e9}
ours, current = {}, None
for line in open(sys.argv[2]):
    m = re.match(r"^(kernels_\S+)", line)
    if m:
        current = m.group(1)
    t = re.search(r"time:\s+\[\S+ \S+ (\S+) (\S+)", line)
    if t and current:
        ours[current] = float(t.group(1)) * unit[t.group(2)] / 1024
        current = None
print(f"\n{'robot':<7}{'dof':>4}  {'kernel':<10}{'Pinocchio C++':>14}{'robotid per sample':>20}{'robotid batched':>17}{'batched ÷ Pinocchio':>21}")
for name, (dof, reg, tau) in pin.items():
    for kernel, theirs in (("regressor", reg), ("rnea", tau)):
        one = ours.get(f"kernels_{name}/{kernel}/per_sample")
        many = ours.get(f"kernels_{name}/{kernel}/batched")
        if one is None or many is None:
            sys.exit(f"no robotid timing for {name} {kernel}")
        print(f"{name:<7}{dof:>4}  {kernel:<10}{theirs:>11.0f} ns{one:>17.0f} ns{many:>14.0f} ns{theirs / many:>19.2f}×")
EOF
