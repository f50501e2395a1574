// A tiny baker embedding guidebake's kernels through the C ABI, in C++17: 32 texels under a
// square area light, clustered, each cluster learning a guide over 4 iterations, 8-wide
// warps, packets traced through a BVH built by the ABI's helper, Graybill-Deal with the
// global rho, checked against the analytic irradiance. It prints what
// kernels/examples/embed.rs and examples/c/embed.c print, bit for bit (CI diffs them).
// Build: c++ -std=c++17 -O2 -ffp-contract=off -Icapi/include embed.cpp -Ltarget/debug -lguidebake_capi
#include <array>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <stdexcept>
#include <string>
#include <vector>

#include "guidebake.h"

namespace {

constexpr int N = 64, K = 4, TEXELS = 32, NODES = 1024;
constexpr uint32_t SEED = 7;
constexpr float LIGHT[3] = {4.0f, 3.5f, 3.0f};  // radiance of prims 0, 1
constexpr float PI_F = 3.14159265358979323846f;
using Vec = std::array<float, 3>;

// Every ABI call returns a status; a failure becomes an exception carrying the message.
void check(GuidebakeStatus status, const char* what) {
    if (status != GUIDEBAKE_STATUS_OK)
        throw std::runtime_error(std::string(what) + ": " + guidebake_last_error());
}
#define CHECK(call) check((call), #call)

// Caller-owned storage at the alignment the ABI asks for.
struct Aligned {
    std::unique_ptr<void, decltype(&std::free)> ptr;
    size_t bytes;
    Aligned(size_t align, size_t n) : ptr(std::aligned_alloc(align, n), &std::free), bytes(n) {
        if (!ptr) throw std::bad_alloc();
    }
    template <class T> T* as() const { return static_cast<T*>(ptr.get()); }
};

// The light (prims 0, 1) at z = 1 and two black walls at x = +-3 (prims 2..5).
constexpr float QUADS[3][4][3] = {
    {{-0.5f, -0.5f, 1}, {0.5f, -0.5f, 1}, {0.5f, 0.5f, 1}, {-0.5f, 0.5f, 1}},
    {{3, -3, 0}, {3, 3, 0}, {3, 3, 2}, {3, -3, 2}},
    {{-3, -3, 0}, {-3, 3, 0}, {-3, 3, 2}, {-3, -3, 2}},
};

void texel(int i, Vec& p, Vec& n) {
    const double a = 40.0 * (3.14159265358979323846 / 180.0);  // texels 16..31 lean to +x
    p = {-0.375f + 0.25f * float(i % 4), -0.375f + 0.25f * float((i / 4) % 4), 0.0f};
    n = i < 16 ? Vec{0.0f, 0.0f, 1.0f} : Vec{float(std::sin(a)), 0.0f, float(std::cos(a))};
}

std::array<double, 3> unit(std::array<double, 3> w) {
    const double l = std::sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    return {w[0] / l, w[1] / l, w[2] / l};
}

// Lambert's polygon formula: irradiance per unit radiance from the light.
double analytic(const Vec& p, const Vec& n) {
    double sum = 0.0;
    for (int k = 0; k < 4; k++) {
        std::array<double, 3> a, b;
        for (int j = 0; j < 3; j++) {
            a[j] = double(QUADS[0][k][j]) - double(p[j]);
            b[j] = double(QUADS[0][(k + 1) % 4][j]) - double(p[j]);
        }
        a = unit(a), b = unit(b);
        const double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        const auto c = unit({a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]});
        sum += std::acos(dot) * (double(n[0]) * c[0] + double(n[1]) * c[1] + double(n[2]) * c[2]);
    }
    return 0.5 * std::fabs(sum);
}

uint64_t bits(double x) {
    uint64_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
}

int bake() {
    if (guidebake_abi_version() != GUIDEBAKE_ABI_VERSION) throw std::runtime_error("ABI mismatch");
    std::vector<float> verts;
    constexpr int CORNERS[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (int t = 0; t < 6; t++)
        for (int v : CORNERS[t % 2])
            for (float x : QUADS[t / 2][v]) verts.push_back(x);
    size_t node_cap, tri_cap, node_count;
    CHECK(guidebake_bvh_build_sizes(6, &node_cap, &tri_cap));
    Aligned nodes(guidebake_bvh_node_align(), node_cap * sizeof(GuidebakeBvhNode));
    std::vector<GuidebakeTri> tris(tri_cap);
    CHECK(guidebake_bvh_build(verts.data(), 6, nodes.as<GuidebakeBvhNode>(), node_cap, tris.data(), tri_cap,
                              &node_count));
    GuidebakeBvh bvh;
    CHECK(guidebake_bvh_view(nodes.as<GuidebakeBvhNode>(), node_count, tris.data(), tris.size(), &bvh));

    std::vector<Vec> pos(TEXELS), nrm(TEXELS);
    for (int i = 0; i < TEXELS; i++) texel(i, pos[i], nrm[i]);
    GuidebakeClusterParams cp = guidebake_cluster_params_default();
    cp.max_texels = 8;
    std::vector<uint32_t> perm(TEXELS);
    std::vector<GuidebakeClusterRange> ranges(TEXELS);
    size_t clusters;
    CHECK(guidebake_build_clusters(pos[0].data(), nrm[0].data(), TEXELS, &cp, perm.data(), perm.size(),
                                   ranges.data(), ranges.size(), &clusters));

    std::vector<uint32_t> order(N), packet_order(N);
    CHECK(guidebake_presort(N, order.data(), order.size()));
    Aligned storage(guidebake_guide_node_align(), NODES * guidebake_guide_node_size());
    std::vector<GuidebakeRecord> records;
    std::vector<std::array<GuidebakeWelford, K>> batches(TEXELS);
    std::vector<int> cluster_of(TEXELS);
    for (size_t c = 0; c < clusters; c++) {
        for (int k = 0; k < K; k++) {
            GuidebakeGuide g;
            if (k == 0)
                CHECK(guidebake_guide_uniform(storage.ptr.get(), storage.bytes, &g));
            else
                CHECK(guidebake_guide_build(records.data(), records.size(), nullptr, storage.ptr.get(),
                                            storage.bytes, &g, nullptr));
            records.clear();
            for (uint32_t j = ranges[c].start; j < ranges[c].end; j++) {
                const int t = int(perm[j]);
                cluster_of[t] = int(c);
                float tb[3], bb[3];
                uint32_t r[2];
                CHECK(guidebake_welford_init(&batches[t][k]));
                CHECK(guidebake_orthonormal_basis(nrm[t].data(), tb, bb));
                CHECK(guidebake_rotation(SEED, uint64_t(t), uint32_t(k), r));
                CHECK(guidebake_reorder_after_rotation(order.data(), N, r, packet_order.data(), N));
                for (int s = 0; s < N; s += 8) {
                    float x[8], y[8], wx[8], wy[8], pdf[8], lx[8], ly[8], lz[8];
                    CHECK(guidebake_packet_points8(&packet_order[s], 8, r, x, y));
                    CHECK(guidebake_guide_sample8(&g, x, y, wx, wy, pdf));
                    CHECK(guidebake_sample_cosine_hemisphere8(wx, wy, lx, ly, lz));
                    GuidebakeRay8 rays{};
                    GuidebakeHit8 hits{};
                    for (int l = 0; l < 8; l++) {
                        for (int a = 0; a < 3; a++) {
                            rays.org[a][l] = pos[t][a];
                            rays.dir[a][l] = tb[a] * lx[l] + bb[a] * ly[l] + nrm[t][a] * lz[l];
                        }
                        rays.tmax[l] = INFINITY;
                        hits.t[l] = INFINITY, hits.prim[l] = GUIDEBAKE_NO_HIT;
                    }
                    CHECK(guidebake_intersect8(&bvh, &rays, &hits, nullptr));
                    for (int l = 0; l < 8; l++) {
                        float rad[3], sample[3];
                        for (int ch = 0; ch < 3; ch++) {
                            rad[ch] = hits.prim[l] < 2 ? LIGHT[ch] : 0.0f;
                            sample[ch] = PI_F * rad[ch] / pdf[l];  // pi L / pdf: irradiance
                        }
                        CHECK(guidebake_welford_push(&batches[t][k], sample));
                        const float lum = float(guidebake_luminance(rad[0], rad[1], rad[2]));
                        records.push_back(GuidebakeRecord{{wx[l], wy[l]}, lum / pdf[l]});
                    }
                }
            }
        }
    }

    GuidebakeRho acc;
    double rho;
    CHECK(guidebake_rho_init(&acc));
    for (auto& b : batches) {
        GuidebakeEstimate avg, gd;
        CHECK(guidebake_combine_average(b.data(), K, &avg));
        CHECK(guidebake_combine_default(b.data(), K, &gd));
        CHECK(guidebake_rho_add_texel(&acc, &avg, &gd));
    }
    CHECK(guidebake_rho_value(&acc, &rho));
    std::printf("guidebake embed: %d texels in %zu clusters, %d iterations of %d samples, rho = %016" PRIx64
                " (%.6f)\n", TEXELS, clusters, K, N, bits(rho), rho);
    const double light = guidebake_luminance(LIGHT[0], LIGHT[1], LIGHT[2]);
    double total = 0, reference = 0, variance = 0, worst = 0;
    for (int t = 0; t < TEXELS; t++) {
        GuidebakeEstimate gd;
        CHECK(guidebake_combine_default(batches[t].data(), K, &gd));
        double lum = gd.luminance * rho, precision = 0;
        for (auto& b : batches[t]) {  // the combination's deviation: 1 / sum n_k / var_k
            GuidebakeWelfordStats st;
            CHECK(guidebake_welford_stats(&b, &st));
            precision += double(st.count) / st.variance[3];
        }
        const double sigma = std::sqrt(1.0 / precision), exact = light * analytic(pos[t], nrm[t]);
        const double z = (lum - exact) / sigma;
        std::printf("texel %2d: cluster %d, luminance %016" PRIx64 " = %.6f, analytic %.6f, z = %+.2f\n", t,
                    cluster_of[t], bits(lum), lum, exact, z);
        total += lum, reference += exact, variance += sigma * sigma;
        worst = std::fabs(z) > worst ? std::fabs(z) : worst;
    }
    const double z = (total - reference) / std::sqrt(variance);
    std::printf("total: %016" PRIx64 " = %.6f, analytic %.6f, z = %+.2f\n", bits(total), total, reference, z);
    if (worst < 3.0 && std::fabs(z) < 3.0) {
        std::printf("OK: every texel and the total within 3 sigma of the analytic irradiance\n");
        return 0;
    }
    std::printf("FAIL: largest |z| %.2f, total z %+.2f\n", worst, z);
    return 1;
}

}  // namespace

int main() {
    try {
        return bake();
    } catch (const std::exception& e) {
        std::fprintf(stderr, "%s\n", e.what());
        return 2;
    }
}
