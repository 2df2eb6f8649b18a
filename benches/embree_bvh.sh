#!/usr/bin/env bash
# BVH build time and ray throughput of chiaro's BVH (single rays, and packets
# of 8: camera rays in 4 x 2 tiles, random rays 8 in a row) next to native
# Embree 3 (rtcIntersect1, rtcIntersect16), on the same 1,003,520-triangle
# grid of icospheres and the same rays (a pinhole camera over the grid and
# uniformly random rays), both on $THREADS threads.
#
#   benches/embree_bvh.sh [THREADS] [REPS] [PAIRS]
#
# Runs chiaro then Embree PAIRS times (default 3), alternating, so that each
# chiaro figure has an Embree figure taken seconds apart under the same load.
# Needs root for apt-get (libembree-dev, g++) the first time. The chiaro
# side (crates/chiaro-ray/examples/bvh_bench.rs) writes the mesh and rays to
# $OUT/wl_*.bin, which the Embree program below then reads, so both trace
# identical rays. The Embree program below traces them with rtcIntersect1 /
# rtcIntersect16 (OpenMP dynamic schedule) and reports the
# process CPU time of every measured interval, the figure chiaro also prints:
# on a machine shared with other work, CPU time leaves out the time a
# process spent descheduled. OMP_WAIT_POLICY=passive keeps idle OpenMP
# threads from spinning into that CPU time. Embree's build runs on its own
# TBB threads, which do spin, so compare builds by wall clock on a quiet
# machine (benches/wait_quiet.sh). EMBREE_ISA (e.g. avx2) caps the kernels
# Embree picks (its device config `isa=`), to see what an AVX-512 host gives it.
# CHIARO_KERNELS="auto baseline" runs chiaro once per listed value of
# CHIARO_KERNEL in each pair (the single-ray kernel: auto picks AVX-512 where
# the CPU has it, baseline keeps the build's x86-64-v3), to compare kernels.
set -euo pipefail
THREADS=${1:-2}
REPS=${2:-5}
PAIRS=${3:-3}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${OUT:-$ROOT/target/bench-embree}
mkdir -p "$OUT"

if ! [ -f /usr/include/embree3/rtcore.h ] || ! command -v g++ >/dev/null; then
    apt-get update -qq && apt-get install -y -qq libembree-dev g++ >/dev/null
fi
cat > "$OUT/embree3_cpu.cpp" <<'CPP'
// Native Embree 3 on the wl_*.bin workload,
// with wall-clock and process-CPU time per measurement.
#include <embree3/rtcore.h>
#include <omp.h>
#include <time.h>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
static std::string wl(const char* n) { const char* d = getenv("PEERS_OUT"); return std::string(d ? d : "peers-out") + "/wl_" + n + ".bin"; }
static std::vector<char> load(const std::string& p) {
  FILE* f = fopen(p.c_str(), "rb"); if (!f) { perror(p.c_str()); exit(1); }
  fseek(f, 0, SEEK_END); long n = ftell(f); fseek(f, 0, SEEK_SET);
  std::vector<char> b(n); if (fread(b.data(), 1, n, f) != (size_t)n) { perror(p.c_str()); exit(1); } fclose(f); return b;
}
static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
static double cpu() { timespec t; clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t); return t.tv_sec + 1e-9 * t.tv_nsec; }
static double med(std::vector<double> v) { std::sort(v.begin(), v.end()); return v[v.size() / 2]; }
int main(int argc, char** argv) {
  int threads = argc > 1 ? atoi(argv[1]) : 2, reps = argc > 2 ? atoi(argv[2]) : 5;
  omp_set_num_threads(threads);
  auto V = load(wl("V")), F = load(wl("F"));
  size_t nv = V.size() / 12, nf = F.size() / 12;
  const char* isa = getenv("EMBREE_ISA");
  char cfg[96]; snprintf(cfg, sizeof cfg, isa && *isa ? "threads=%d,isa=%s" : "threads=%d", threads, isa);
  RTCDevice dev = rtcNewDevice(cfg);
  std::vector<double> bw, bc; RTCScene scene = nullptr;
  for (int r = 0; r < reps; r++) {
    if (scene) rtcReleaseScene(scene);
    scene = rtcNewScene(dev);
    RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    float* vb = (float*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv); memcpy(vb, V.data(), nv * 12);
    unsigned* ib = (unsigned*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nf); memcpy(ib, F.data(), nf * 12);
    rtcCommitGeometry(g); rtcAttachGeometry(scene, g); rtcReleaseGeometry(g);
    double w0 = now(), c0 = cpu(); rtcCommitScene(scene); bw.push_back(now() - w0); bc.push_back(cpu() - c0);
  }
  printf("embree %s, tris=%zu, '%s': BVH build (rtcCommitScene) median %.3fs (min %.3fs, cpu %.3fs)\n", RTC_VERSION_STRING, nf, cfg, med(bw), *std::min_element(bw.begin(), bw.end()), med(bc));
  const char* names[2] = {"coherent(camera)", "incoherent(random)"};
  const char* files[2][2] = {{"O", "D"}, {"Or", "Dr"}};
  for (int s = 0; s < 2; s++) {
    auto Ob = load(wl(files[s][0])), Db = load(wl(files[s][1]));
    const float* O = (float*)Ob.data(); const float* D = (float*)Db.data();
    long n = Ob.size() / 12;
    for (int mode = 0; mode < 2; mode++) {
      std::vector<double> ts, cs; long hits = 0;
      for (int r = 0; r < reps; r++) {
        hits = 0; double a = now(), c0 = cpu();
        if (mode == 0) {
          #pragma omp parallel for schedule(dynamic, 4096) reduction(+ : hits)
          for (long i = 0; i < n; i++) {
            RTCIntersectContext ctx; rtcInitIntersectContext(&ctx);
            RTCRayHit rh; rh.ray.org_x = O[3 * i]; rh.ray.org_y = O[3 * i + 1]; rh.ray.org_z = O[3 * i + 2];
            rh.ray.dir_x = D[3 * i]; rh.ray.dir_y = D[3 * i + 1]; rh.ray.dir_z = D[3 * i + 2];
            rh.ray.tnear = 0.f; rh.ray.tfar = 1e30f; rh.ray.mask = -1; rh.ray.flags = 0; rh.ray.time = 0;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID; rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh); hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
          }
        } else {
          #pragma omp parallel for schedule(dynamic, 256) reduction(+ : hits)
          for (long p = 0; p < n / 16; p++) {
            RTCIntersectContext ctx; rtcInitIntersectContext(&ctx);
            ctx.flags = s == 0 ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
            alignas(64) RTCRayHit16 rh; alignas(64) int valid[16];
            for (int k = 0; k < 16; k++) {
              long i = p * 16 + k; valid[k] = -1;
              rh.ray.org_x[k] = O[3 * i]; rh.ray.org_y[k] = O[3 * i + 1]; rh.ray.org_z[k] = O[3 * i + 2];
              rh.ray.dir_x[k] = D[3 * i]; rh.ray.dir_y[k] = D[3 * i + 1]; rh.ray.dir_z[k] = D[3 * i + 2];
              rh.ray.tnear[k] = 0.f; rh.ray.tfar[k] = 1e30f; rh.ray.mask[k] = -1; rh.ray.flags[k] = 0; rh.ray.time[k] = 0;
              rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID; rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
            }
            rtcIntersect16(valid, scene, &ctx, &rh);
            for (int k = 0; k < 16; k++) hits += rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
          }
        }
        ts.push_back(now() - a); cs.push_back(cpu() - c0);
      }
      double m = med(ts), c = med(cs);
      printf("%-20s %-14s threads=%d: median %.4fs -> %.2f Mrays/s (min %.4f, hit rate %.3f, cpu %.4fs -> %.2f Mrays/s cpu-normalised)\n",
             names[s], mode == 0 ? "rtcIntersect1" : "rtcIntersect16", threads, m, n / m / 1e6,
             *std::min_element(ts.begin(), ts.end()), (double)hits / n, c, n / (c / threads) / 1e6);
    }
  }
  rtcReleaseScene(scene); rtcReleaseDevice(dev);
}
CPP
if ! [ -x "$OUT/embree3_cpu" ] || [ "$OUT/embree3_cpu.cpp" -nt "$OUT/embree3_cpu" ]; then
    g++ -O2 -fopenmp -o "$OUT/embree3_cpu" "$OUT/embree3_cpu.cpp" -lembree3
fi

(cd "$ROOT" && cargo build --release -q -p chiaro-ray --example bvh_bench)
EMBREE_VERSION=$(dpkg-query -W -f='${Version}' libembree3-3 2>/dev/null || echo 3)
for pair in $(seq "$PAIRS"); do
    echo "== pair $pair, load: $(cut -d' ' -f1-3 /proc/loadavg)"
    DUMP=()
    [ "$pair" = 1 ] && DUMP=(--dump "$OUT")
    for kernel in ${CHIARO_KERNELS:-auto}; do
        echo "-- chiaro, CHIARO_KERNEL=$kernel (crates/chiaro-ray/examples/bvh_bench.rs)"
        CHIARO_KERNEL=$kernel "$ROOT/target/release/examples/bvh_bench" --threads "$THREADS" --reps "$REPS" "${DUMP[@]}"
        DUMP=()
    done
    echo "-- Embree $EMBREE_VERSION (embree3_cpu)"
    OMP_WAIT_POLICY=passive PEERS_OUT="$OUT" "$OUT/embree3_cpu" "$THREADS" "$REPS"
done
