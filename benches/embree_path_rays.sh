#!/usr/bin/env bash
# The path tracer's own rays on Mitsuba's Cornell box, through chiaro's BVH
# and through native Embree 3, one thread each: where does the path tracer's
# time per ray stand against the ray tracing kernel that Mitsuba's llvm
# variant calls?
#
#   benches/embree_path_rays.sh [SPP=16] [REPS=5] [PAIRS=3] [SCENE=scenes/mitsuba-cbox.toml]
#
# crates/chiaro-ray/examples/path_rays.rs renders the scene once on one
# thread, recording every closest-hit and shadow ray, writes the triangles
# and the rays to $OUT/wl_{V,F,C,S}.bin, and times SceneBvh on them in the
# renderer's order (one call per ray through `&dyn Accelerator`). The Embree
# program below traces the same rays in the same order: rtcIntersect1 /
# rtcOccluded1 per ray, and rtcIntersect16 / rtcOccluded16 on each 16
# consecutive rays (flagged incoherent; the renderer traces a pixel's
# samples together, so consecutive rays are one pixel's). The two alternate
# PAIRS times. Needs libembree-dev and g++ (apt-get, as root, the first
# time). With $MITSUBA_VENV set (a venv with the `mitsuba` wheel), the same
# program is also built against the wheel's own libembree3.so (Embree
# 3.13.4, its API in namespace `mitsuba`, reached through a copy of the
# Debian headers with that namespace switched on): the build that Mitsuba's
# llvm variant calls. Its lines print the header's version string; the
# library is the wheel's.
set -euo pipefail
SPP=${1:-16}
REPS=${2:-5}
PAIRS=${3:-3}
SCENE=${4:-scenes/mitsuba-cbox.toml}
ROOT=$(cd "$(dirname "$0")/.." && pwd)
OUT=${OUT:-$ROOT/target/bench-embree-path}
mkdir -p "$OUT"
if ! [ -f /usr/include/embree3/rtcore.h ] || ! command -v g++ >/dev/null; then
    apt-get update -qq && apt-get install -y -qq libembree-dev g++ >/dev/null
fi
cat > "$OUT/embree_path_rays.cpp" <<'CPP'
// Native Embree 3 on path_rays' wl_{V,F,C,S}.bin, one thread.
#include <embree3/rtcore.h>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
static std::vector<char> load(const std::string& p) {
  FILE* f = fopen(p.c_str(), "rb"); if (!f) { perror(p.c_str()); exit(1); }
  fseek(f, 0, SEEK_END); long n = ftell(f); fseek(f, 0, SEEK_SET);
  std::vector<char> b(n); if (fread(b.data(), 1, n, f) != (size_t)n) { perror(p.c_str()); exit(1); } fclose(f); return b;
}
static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }
static double med(std::vector<double> v) { std::sort(v.begin(), v.end()); return v[v.size() / 2]; }
// Lane k of a 16-ray packet from the recorded ray r (origin, direction, tnear, tfar).
template <class Ray16> static void set_lane(Ray16& ray, int k, const float* r) {
  ray.org_x[k] = r[0]; ray.org_y[k] = r[1]; ray.org_z[k] = r[2];
  ray.dir_x[k] = r[3]; ray.dir_y[k] = r[4]; ray.dir_z[k] = r[5];
  ray.tnear[k] = r[6]; ray.tfar[k] = r[7]; ray.mask[k] = -1; ray.flags[k] = 0; ray.time[k] = 0;
}
int main(int argc, char** argv) {
  std::string dir = argc > 1 ? argv[1] : ".";
  int reps = argc > 2 ? atoi(argv[2]) : 5;
  auto V = load(dir + "/wl_V.bin"), F = load(dir + "/wl_F.bin"), C = load(dir + "/wl_C.bin"), S = load(dir + "/wl_S.bin");
  size_t nv = V.size() / 12, nf = F.size() / 12;
  RTCDevice dev = rtcNewDevice("threads=1");
  RTCScene scene = rtcNewScene(dev);
  RTCGeometry g = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
  float* vb = (float*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 12, nv); memcpy(vb, V.data(), nv * 12);
  unsigned* ib = (unsigned*)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nf); memcpy(ib, F.data(), nf * 12);
  rtcCommitGeometry(g); rtcAttachGeometry(scene, g); rtcReleaseGeometry(g); rtcCommitScene(scene);
  const float* c = (const float*)C.data(); long nc = C.size() / 32;
  const float* s = (const float*)S.data(); long ns = S.size() / 32;
  std::vector<double> t1, o1, t16, o16;
  for (int rep = 0; rep < reps; rep++) {
    long hits = 0, occ = 0, hits16 = 0, occ16 = 0; double a = now();
    for (long i = 0; i < nc; i++) {
      const float* r = c + 8 * i;
      RTCIntersectContext ctx; rtcInitIntersectContext(&ctx);
      RTCRayHit rh; rh.ray.org_x = r[0]; rh.ray.org_y = r[1]; rh.ray.org_z = r[2];
      rh.ray.dir_x = r[3]; rh.ray.dir_y = r[4]; rh.ray.dir_z = r[5];
      rh.ray.tnear = r[6]; rh.ray.tfar = r[7]; rh.ray.mask = -1; rh.ray.flags = 0; rh.ray.time = 0;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID; rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, &ctx, &rh); hits += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
    }
    double b = now();
    for (long i = 0; i < ns; i++) {
      const float* r = s + 8 * i;
      RTCIntersectContext ctx; rtcInitIntersectContext(&ctx);
      RTCRay ray; ray.org_x = r[0]; ray.org_y = r[1]; ray.org_z = r[2];
      ray.dir_x = r[3]; ray.dir_y = r[4]; ray.dir_z = r[5];
      ray.tnear = r[6]; ray.tfar = r[7]; ray.mask = -1; ray.flags = 0; ray.time = 0;
      rtcOccluded1(scene, &ctx, &ray); occ += ray.tfar < 0;
    }
    double d = now();
    for (long p = 0; p + 16 <= nc; p += 16) {
      RTCIntersectContext ctx; rtcInitIntersectContext(&ctx); ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
      alignas(64) RTCRayHit16 rh; alignas(64) int valid[16];
      for (int k = 0; k < 16; k++) {
        valid[k] = -1; set_lane(rh.ray, k, c + 8 * (p + k));
        rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID; rh.hit.instID[0][k] = RTC_INVALID_GEOMETRY_ID;
      }
      rtcIntersect16(valid, scene, &ctx, &rh);
      for (int k = 0; k < 16; k++) hits16 += rh.hit.geomID[k] != RTC_INVALID_GEOMETRY_ID;
    }
    double e = now();
    for (long p = 0; p + 16 <= ns; p += 16) {
      RTCIntersectContext ctx; rtcInitIntersectContext(&ctx); ctx.flags = RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
      alignas(64) RTCRay16 ray; alignas(64) int valid[16];
      for (int k = 0; k < 16; k++) {
        valid[k] = -1; set_lane(ray, k, s + 8 * (p + k));
      }
      rtcOccluded16(valid, scene, &ctx, &ray);
      for (int k = 0; k < 16; k++) occ16 += ray.tfar[k] < 0;
    }
    double f = now();
    t1.push_back((b - a) * 1e9 / nc); o1.push_back((d - b) * 1e9 / ns);
    t16.push_back((e - d) * 1e9 / (nc / 16 * 16)); o16.push_back((f - e) * 1e9 / (ns / 16 * 16));
    printf("rep %d: rtcIntersect1 %.1f ns/ray (%ld hits), rtcOccluded1 %.1f ns/ray (%ld occluded), x16: %.1f / %.1f ns/ray (%ld, %ld)\n",
           rep, t1.back(), hits, o1.back(), occ, t16.back(), o16.back(), hits16, occ16);
  }
  printf("embree %s median: closest %.1f ns/ray (x16 %.1f), shadow %.1f ns/ray (x16 %.1f)\n", RTC_VERSION_STRING, med(t1), med(t16), med(o1), med(o16));
  rtcReleaseScene(scene); rtcReleaseDevice(dev);
}
CPP
if ! [ -x "$OUT/embree_path_rays" ] || [ "$OUT/embree_path_rays.cpp" -nt "$OUT/embree_path_rays" ]; then
    g++ -O2 -o "$OUT/embree_path_rays" "$OUT/embree_path_rays.cpp" -lembree3
fi
MI_EMBREE=
if [ -n "${MITSUBA_VENV:-}" ]; then
    MI_DIR=$(ls -d "$MITSUBA_VENV"/lib/python3*/site-packages/mitsuba | head -1)
    if [ -f "$MI_DIR/libembree3.so" ]; then
        mkdir -p "$OUT/mi-include/embree3"
        cp /usr/include/embree3/*.h "$OUT/mi-include/embree3/"
        sed -i -e 's|/\* #undef EMBREE_API_NAMESPACE \*/|#define EMBREE_API_NAMESPACE|' \
            -e 's|define RTC_NAMESPACE $|define RTC_NAMESPACE mitsuba|' \
            -e 's|namespace  {|namespace mitsuba {|' \
            -e 's|using namespace ;|using namespace mitsuba;|' "$OUT/mi-include/embree3/rtcore_config.h"
        sed 's|#include <embree3/rtcore.h>|#include <embree3/rtcore.h>\nRTC_NAMESPACE_USE|' \
            "$OUT/embree_path_rays.cpp" > "$OUT/embree_path_rays_mitsuba.cpp"
        g++ -O2 -I"$OUT/mi-include" -o "$OUT/embree_path_rays_mitsuba" "$OUT/embree_path_rays_mitsuba.cpp" \
            "$MI_DIR/libembree3.so" -Wl,-rpath,"$MI_DIR"
        MI_EMBREE="$OUT/embree_path_rays_mitsuba"
    fi
fi
(cd "$ROOT" && cargo build --release -q -p chiaro-ray --example path_rays)
for pair in $(seq "$PAIRS"); do
    echo "== pair $pair, load: $(cut -d' ' -f1-3 /proc/loadavg)"
    DUMP=()
    [ "$pair" = 1 ] && DUMP=(--dump "$OUT")
    (cd "$ROOT" && target/release/examples/path_rays "$SCENE" --spp "$SPP" --reps "$REPS" "${DUMP[@]}") | grep -v '^rep '
    "$OUT/embree_path_rays" "$OUT" "$REPS" | grep -v '^rep ' | sed 's/^embree/Debian embree/'
    if [ -n "$MI_EMBREE" ]; then
        "$MI_EMBREE" "$OUT" "$REPS" | grep -v '^rep ' | sed 's/^embree [0-9.]*/the mitsuba wheel'"'"'s embree 3.13.4/'
    fi
done
