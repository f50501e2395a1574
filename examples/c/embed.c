/* A tiny baker embedding guidebake's kernels through the C ABI (capi/include/guidebake.h):
 * 32 texels under a square area light, clustered, each cluster learning a guide over 4
 * iterations, 8-wide warps, packets traced through a BVH built by the ABI's helper,
 * Graybill-Deal with the global rho, checked against the analytic irradiance.
 * It prints what kernels/examples/embed.rs prints, bit for bit (CI diffs the two).
 * Build: cc -std=c11 -O2 -ffp-contract=off -Icapi/include embed.c -Ltarget/debug -lguidebake_capi -lm */
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "guidebake.h"

enum { N = 64, K = 4, SEED = 7, TEXELS = 32, NODES = 1024 };
static const float LIGHT[3] = {4.0f, 3.5f, 3.0f}; /* radiance of prims 0, 1 */
static const float PI_F = 3.14159265358979323846f;

#define CHECK(call)                                                                         \
    do {                                                                                    \
        if ((call) != GUIDEBAKE_STATUS_OK) {                                                \
            fprintf(stderr, "%s failed: %s\n", #call, guidebake_last_error());             \
            exit(2);                                                                        \
        }                                                                                   \
    } while (0)

/* The light (prims 0, 1) at z = 1 and two black walls at x = +-3 (prims 2..5). */
static const float QUADS[3][4][3] = {
    {{-0.5f, -0.5f, 1}, {0.5f, -0.5f, 1}, {0.5f, 0.5f, 1}, {-0.5f, 0.5f, 1}},
    {{3, -3, 0}, {3, 3, 0}, {3, 3, 2}, {3, -3, 2}},
    {{-3, -3, 0}, {-3, 3, 0}, {-3, 3, 2}, {-3, -3, 2}},
};

static void texel(int i, float p[3], float n[3]) {
    double a = 40.0 * (3.14159265358979323846 / 180.0); /* texels 16..31 lean toward +x */
    p[0] = -0.375f + 0.25f * (float)(i % 4);
    p[1] = -0.375f + 0.25f * (float)((i / 4) % 4);
    p[2] = 0.0f;
    n[0] = i < 16 ? 0.0f : (float)sin(a);
    n[1] = 0.0f;
    n[2] = i < 16 ? 1.0f : (float)cos(a);
}

static uint64_t bits(double x) {
    uint64_t b;
    memcpy(&b, &x, sizeof b);
    return b;
}

static void unit(double w[3]) {
    double l = sqrt(w[0] * w[0] + w[1] * w[1] + w[2] * w[2]);
    w[0] /= l, w[1] /= l, w[2] /= l;
}

/* Lambert's polygon formula: irradiance per unit radiance from the light. */
static double analytic(const float p[3], const float n[3]) {
    double sum = 0.0;
    for (int k = 0; k < 4; k++) {
        double a[3], b[3], c[3];
        for (int j = 0; j < 3; j++) {
            a[j] = (double)QUADS[0][k][j] - (double)p[j];
            b[j] = (double)QUADS[0][(k + 1) % 4][j] - (double)p[j];
        }
        unit(a), unit(b);
        double dot = a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        c[0] = a[1] * b[2] - a[2] * b[1], c[1] = a[2] * b[0] - a[0] * b[2], c[2] = a[0] * b[1] - a[1] * b[0];
        unit(c);
        sum += acos(dot) * ((double)n[0] * c[0] + (double)n[1] * c[1] + (double)n[2] * c[2]);
    }
    return 0.5 * fabs(sum);
}

int main(void) {
    if (guidebake_abi_version() != GUIDEBAKE_ABI_VERSION) return fprintf(stderr, "ABI mismatch\n"), 2;
    /* The BVH, by the ABI's helper, into caller-owned, 64-aligned storage. */
    float verts[6 * 9];
    static const int CORNERS[2][3] = {{0, 1, 2}, {0, 2, 3}};
    for (int t = 0; t < 6; t++)
        for (int v = 0; v < 3; v++)
            for (int j = 0; j < 3; j++) verts[9 * t + 3 * v + j] = QUADS[t / 2][CORNERS[t % 2][v]][j];
    size_t node_cap, tri_cap, node_count;
    CHECK(guidebake_bvh_build_sizes(6, &node_cap, &tri_cap));
    GuidebakeBvhNode *nodes = aligned_alloc(guidebake_bvh_node_align(), node_cap * sizeof *nodes);
    GuidebakeTri *tris = malloc(tri_cap * sizeof *tris);
    GuidebakeBvh bvh;
    CHECK(guidebake_bvh_build(verts, 6, nodes, node_cap, tris, tri_cap, &node_count));
    CHECK(guidebake_bvh_view(nodes, node_count, tris, tri_cap, &bvh));

    float pos[TEXELS][3], nrm[TEXELS][3];
    for (int i = 0; i < TEXELS; i++) texel(i, pos[i], nrm[i]);
    GuidebakeClusterParams cp = guidebake_cluster_params_default();
    cp.max_texels = 8;
    uint32_t perm[TEXELS];
    GuidebakeClusterRange ranges[TEXELS];
    size_t clusters;
    CHECK(guidebake_build_clusters(&pos[0][0], &nrm[0][0], TEXELS, &cp, perm, TEXELS, ranges, TEXELS, &clusters));

    uint32_t order[N], packet_order[N];
    CHECK(guidebake_presort(N, order, N));
    size_t node_size = guidebake_guide_node_size();
    void *storage = aligned_alloc(guidebake_guide_node_align(), NODES * node_size);
    GuidebakeRecord records[8 * N];
    GuidebakeWelford batches[TEXELS][K];
    int cluster_of[TEXELS];
    for (size_t c = 0; c < clusters; c++) {
        size_t nrec = 0;
        for (int k = 0; k < K; k++) {
            GuidebakeGuide g;
            if (k == 0) CHECK(guidebake_guide_uniform(storage, NODES * node_size, &g));
            else CHECK(guidebake_guide_build(records, nrec, NULL, storage, NODES * node_size, &g, NULL));
            nrec = 0;
            for (uint32_t j = ranges[c].start; j < ranges[c].end; j++) {
                int t = (int)perm[j];
                float tb[3], bb[3];
                uint32_t r[2];
                cluster_of[t] = (int)c;
                CHECK(guidebake_welford_init(&batches[t][k]));
                CHECK(guidebake_orthonormal_basis(nrm[t], tb, bb));
                CHECK(guidebake_rotation(SEED, (uint64_t)t, (uint32_t)k, r));
                CHECK(guidebake_reorder_after_rotation(order, N, r, packet_order, N));
                for (int s = 0; s < N; s += 8) {
                    float x[8], y[8], wx[8], wy[8], pdf[8], lx[8], ly[8], lz[8];
                    GuidebakeRay8 rays;
                    GuidebakeHit8 hits;
                    CHECK(guidebake_packet_points8(&packet_order[s], 8, r, x, y));
                    CHECK(guidebake_guide_sample8(&g, x, y, wx, wy, pdf));
                    CHECK(guidebake_sample_cosine_hemisphere8(wx, wy, lx, ly, lz));
                    for (int l = 0; l < 8; l++) {
                        for (int a = 0; a < 3; a++) {
                            rays.org[a][l] = pos[t][a];
                            rays.dir[a][l] = tb[a] * lx[l] + bb[a] * ly[l] + nrm[t][a] * lz[l];
                        }
                        rays.tmin[l] = 0.0f, rays.tmax[l] = INFINITY;
                        hits.t[l] = INFINITY, hits.u[l] = hits.v[l] = 0.0f, hits.prim[l] = GUIDEBAKE_NO_HIT;
                    }
                    CHECK(guidebake_intersect8(&bvh, &rays, &hits, NULL));
                    for (int l = 0; l < 8; l++) {
                        float rad[3], sample[3];
                        for (int ch = 0; ch < 3; ch++) {
                            rad[ch] = hits.prim[l] < 2 ? LIGHT[ch] : 0.0f;
                            sample[ch] = PI_F * rad[ch] / pdf[l]; /* pi L / pdf: irradiance */
                        }
                        CHECK(guidebake_welford_push(&batches[t][k], sample));
                        float lum = (float)guidebake_luminance(rad[0], rad[1], rad[2]);
                        records[nrec++] = (GuidebakeRecord){{wx[l], wy[l]}, lum / pdf[l]};
                    }
                }
            }
        }
    }

    GuidebakeRho acc;
    double rho;
    CHECK(guidebake_rho_init(&acc));
    for (int t = 0; t < TEXELS; t++) {
        GuidebakeEstimate avg, gd;
        CHECK(guidebake_combine_average(batches[t], K, &avg));
        CHECK(guidebake_combine_default(batches[t], K, &gd));
        CHECK(guidebake_rho_add_texel(&acc, &avg, &gd));
    }
    CHECK(guidebake_rho_value(&acc, &rho));
    printf("guidebake embed: %d texels in %zu clusters, %d iterations of %d samples, rho = %016" PRIx64
           " (%.6f)\n", TEXELS, clusters, K, N, bits(rho), rho);
    double light = guidebake_luminance(LIGHT[0], LIGHT[1], LIGHT[2]);
    double total = 0, reference = 0, variance = 0, worst = 0;
    for (int t = 0; t < TEXELS; t++) {
        GuidebakeEstimate gd;
        CHECK(guidebake_combine_default(batches[t], K, &gd));
        double lum = gd.luminance * rho, precision = 0;
        for (int k = 0; k < K; k++) { /* the combination's deviation: 1 / sum n_k / var_k */
            GuidebakeWelfordStats st;
            CHECK(guidebake_welford_stats(&batches[t][k], &st));
            precision += (double)st.count / st.variance[3];
        }
        double sigma = sqrt(1.0 / precision), exact = light * analytic(pos[t], nrm[t]);
        double z = (lum - exact) / sigma;
        printf("texel %2d: cluster %d, luminance %016" PRIx64 " = %.6f, analytic %.6f, z = %+.2f\n", t,
               cluster_of[t], bits(lum), lum, exact, z);
        total += lum, reference += exact, variance += sigma * sigma;
        worst = fabs(z) > worst ? fabs(z) : worst;
    }
    double z = (total - reference) / sqrt(variance);
    printf("total: %016" PRIx64 " = %.6f, analytic %.6f, z = %+.2f\n", bits(total), total, reference, z);
    free(nodes), free(tris), free(storage);
    if (worst < 3.0 && fabs(z) < 3.0) {
        printf("OK: every texel and the total within 3 sigma of the analytic irradiance\n");
        return 0;
    }
    printf("FAIL: largest |z| %.2f, total z %+.2f\n", worst, z);
    return 1;
}
