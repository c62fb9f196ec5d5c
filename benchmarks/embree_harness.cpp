// Embree's oriented-disc query on the same discs and rays as the core: the speed reference
// of benchmarks/trace_throughput.py (issue #12). Built by that script against Debian's
// libembree-dev (Embree 3):
//
//   g++ -O2 -std=c++17 embree_harness.cpp -o embree_harness -lembree3 -pthread
//   embree_harness discs.f32 rays.f32 hits.f32 threads rounds
//
// discs.f32: n x 7 float32 (cx cy cz r nx ny nz); rays.f32: m x 6 float32 (ox oy oz dx dy dz),
// row-major pixel order of a width x height image whose width is the first line of stdin.
// Writes m float32 hit distances (inf on a miss) to hits.f32 (from rtcIntersect1), and prints
// one JSON line: build seconds (quality medium) and the median seconds of `rounds` runs of
// rtcIntersect1 (one ray at a time) and rtcIntersect16 (4x4 pixel packets) on `threads`.
#include <embree3/rtcore.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <limits>
#include <thread>
#include <vector>

namespace {

std::vector<float> read_floats(const char *path) {
    std::ifstream f(path, std::ios::binary | std::ios::ate);
    if (!f) {
        std::fprintf(stderr, "cannot read %s\n", path);
        std::exit(2);
    }
    const std::streamsize bytes = f.tellg();
    f.seekg(0);
    std::vector<float> v(size_t(bytes) / sizeof(float));
    f.read(reinterpret_cast<char *>(v.data()), bytes);
    return v;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Runs task(chunk) over `chunks` on `threads` threads pulling from a counter.
template <class Task>
void parallel(size_t chunks, int threads, Task task) {
    std::atomic<size_t> next{0};
    auto worker = [&] {
        for (size_t c; (c = next.fetch_add(1)) < chunks;) task(c);
    };
    std::vector<std::thread> pool;
    for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
    worker();
    for (auto &t : pool) t.join();
}

double median(std::vector<double> v) {
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

}  // namespace

int main(int argc, char **argv) {
    if (argc != 6) {
        std::fprintf(stderr, "usage: embree_harness discs.f32 rays.f32 hits.f32 threads rounds < width\n");
        return 2;
    }
    const std::vector<float> discs = read_floats(argv[1]), rays = read_floats(argv[2]);
    const int threads = std::max(1, std::atoi(argv[4])), rounds = std::max(1, std::atoi(argv[5]));
    size_t width = 0;
    std::cin >> width;
    const size_t n = discs.size() / 7, m = rays.size() / 6;
    if (width == 0 || m % width != 0) {
        std::fprintf(stderr, "the image width must divide the ray count\n");
        return 2;
    }
    const size_t height = m / width;

    RTCDevice device = rtcNewDevice(("threads=" + std::to_string(threads)).c_str());
    RTCScene scene = rtcNewScene(device);
    rtcSetSceneBuildQuality(scene, RTC_BUILD_QUALITY_MEDIUM);
    RTCGeometry geom = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_ORIENTED_DISC_POINT);
    auto *vb = static_cast<float *>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT4, 4 * sizeof(float), n));
    auto *nb = static_cast<float *>(
        rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_NORMAL, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), n));
    for (size_t i = 0; i < n; ++i) {
        const float *d = &discs[7 * i];
        vb[4 * i] = d[0], vb[4 * i + 1] = d[1], vb[4 * i + 2] = d[2], vb[4 * i + 3] = d[3];
        nb[3 * i] = d[4], nb[3 * i + 1] = d[5], nb[3 * i + 2] = d[6];
    }
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    const auto t_build = std::chrono::steady_clock::now();
    rtcCommitScene(scene);
    const double build_s = seconds_since(t_build);

    std::vector<float> hits(m, std::numeric_limits<float>::infinity());
    auto single = [&](size_t chunk) {  // 1024 rays a task
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        for (size_t i = chunk * 1024, end = std::min(m, i + 1024); i < end; ++i) {
            const float *r = &rays[6 * i];
            RTCRayHit rh;
            rh.ray.org_x = r[0], rh.ray.org_y = r[1], rh.ray.org_z = r[2];
            rh.ray.dir_x = r[3], rh.ray.dir_y = r[4], rh.ray.dir_z = r[5];
            rh.ray.tnear = 0.f, rh.ray.tfar = std::numeric_limits<float>::infinity();
            rh.ray.mask = -1, rh.ray.flags = 0, rh.ray.time = 0.f;
            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
            rtcIntersect1(scene, &ctx, &rh);
            hits[i] = rh.hit.geomID == RTC_INVALID_GEOMETRY_ID ? std::numeric_limits<float>::infinity() : rh.ray.tfar;
        }
    };
    const size_t tiles_x = (width + 3) / 4, tiles_y = (height + 3) / 4;
    auto packets = [&](size_t tile) {  // one 4x4 packet a task
        RTCIntersectContext ctx;
        rtcInitIntersectContext(&ctx);
        alignas(64) RTCRayHit16 rh;
        alignas(64) int valid[16];
        const size_t tx = (tile % tiles_x) * 4, ty = (tile / tiles_x) * 4;
        for (int k = 0; k < 16; ++k) {
            const size_t x = tx + size_t(k % 4), y = ty + size_t(k / 4);
            valid[k] = (x < width && y < height) ? -1 : 0;
            const float *r = &rays[6 * (valid[k] ? y * width + x : 0)];
            rh.ray.org_x[k] = r[0], rh.ray.org_y[k] = r[1], rh.ray.org_z[k] = r[2];
            rh.ray.dir_x[k] = r[3], rh.ray.dir_y[k] = r[4], rh.ray.dir_z[k] = r[5];
            rh.ray.tnear[k] = 0.f, rh.ray.tfar[k] = std::numeric_limits<float>::infinity();
            rh.ray.mask[k] = -1, rh.ray.flags[k] = 0, rh.ray.time[k] = 0.f;
            rh.hit.geomID[k] = RTC_INVALID_GEOMETRY_ID;
        }
        rtcIntersect16(valid, scene, &ctx, &rh);
    };
    std::vector<double> t1, t16;
    for (int round = 0; round < rounds; ++round) {  // interleaved, as the core's rows are
        auto t0 = std::chrono::steady_clock::now();
        parallel((m + 1023) / 1024, threads, single);
        t1.push_back(seconds_since(t0));
        t0 = std::chrono::steady_clock::now();
        parallel(tiles_x * tiles_y, threads, packets);
        t16.push_back(seconds_since(t0));
    }
    std::ofstream out(argv[3], std::ios::binary);
    out.write(reinterpret_cast<const char *>(hits.data()), std::streamsize(m * sizeof(float)));
    std::printf("{\"discs\": %zu, \"rays\": %zu, \"threads\": %d, \"build_s\": %.6f, \"intersect1_s\": %.6f, "
                "\"intersect16_s\": %.6f}\n",
                n, m, threads, build_s, median(t1), median(t16));
    rtcReleaseScene(scene);
    rtcReleaseDevice(device);
    return 0;
}
