// A C ABI over xatlas's C++ API (vendor/xatlas.h), so Rust declares plain `extern "C"`
// functions instead of C++-mangled names. Every function is a thin forward.
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include "../vendor/xatlas.h"

extern "C" {

// xatlas frees with `realloc(ptr, 0)` (XA_FREE), also for arrays that never allocated:
// `realloc(nullptr, 0)` is `malloc(0)`, which glibc answers with a real chunk that nothing
// frees — LeakSanitizer found one per mesh xatlas drops (fuzz/corpus/prepare/
// tiny-loose-triangles). A size of 0 frees and returns null here.
static void *gb_realloc(void *ptr, size_t size) {
    if (size == 0) {
        free(ptr);
        return nullptr;
    }
    return realloc(ptr, size);
}

// xatlas prints warnings with printf by default; stdout belongs to the caller (e.g.
// `prepare --json`), so printing is switched off before the first atlas is made. Once only
// (a function-local static is initialised once, thread-safely, in C++11): atlases are made
// on several threads at once (driver/src/prepare/unwrap.rs), and xatlas's globals are
// otherwise read-only.
void *gb_xatlas_create() {
    static const bool init = (xatlas::SetRealloc(gb_realloc), xatlas::SetPrint(nullptr, false), true);
    (void)init;
    return xatlas::Create();
}

void gb_xatlas_destroy(void *atlas) { xatlas::Destroy(static_cast<xatlas::Atlas *>(atlas)); }

// Returns xatlas::AddMeshError (0 = success).
int gb_xatlas_add_mesh(void *atlas, const float *positions, const float *normals,
                       uint32_t vertex_count, const uint32_t *indices, uint32_t index_count) {
    xatlas::MeshDecl decl;
    decl.vertexCount = vertex_count;
    decl.vertexPositionData = positions;
    decl.vertexPositionStride = 3 * sizeof(float);
    decl.vertexNormalData = normals;
    decl.vertexNormalStride = normals ? 3 * sizeof(float) : 0;
    decl.indexCount = index_count;
    decl.indexData = indices;
    decl.indexFormat = xatlas::IndexFormat::UInt32;
    return static_cast<int>(xatlas::AddMesh(static_cast<xatlas::Atlas *>(atlas), decl));
}

void gb_xatlas_compute_charts(void *atlas) {
    xatlas::ComputeCharts(static_cast<xatlas::Atlas *>(atlas));
    xatlas::ParameterizeCharts(static_cast<xatlas::Atlas *>(atlas));
}

void gb_xatlas_pack_charts(void *atlas, float texels_per_unit, uint32_t padding,
                           uint32_t max_chart_size) {
    xatlas::PackOptions o;
    o.texelsPerUnit = texels_per_unit;
    o.resolution = 0;
    o.maxChartSize = max_chart_size;
    o.conservative = true;
    o.padding = padding;
    xatlas::PackCharts(static_cast<xatlas::Atlas *>(atlas), o);
}

// width, height, atlasCount, chartCount, meshCount.
void gb_xatlas_summary(const void *atlas, uint32_t out[5]) {
    const xatlas::Atlas *a = static_cast<const xatlas::Atlas *>(atlas);
    out[0] = a->width;
    out[1] = a->height;
    out[2] = a->atlasCount;
    out[3] = a->chartCount;
    out[4] = a->meshCount;
}

// vertexCount, indexCount, chartCount of output mesh `mesh`.
void gb_xatlas_mesh_counts(const void *atlas, uint32_t mesh, uint32_t out[3]) {
    const xatlas::Mesh &m = static_cast<const xatlas::Atlas *>(atlas)->meshes[mesh];
    out[0] = m.vertexCount;
    out[1] = m.indexCount;
    out[2] = m.chartCount;
}

// Copies output mesh `mesh`: per vertex (u, v) into `uv`, xref into `xref`, atlasIndex into
// `atlas_index`; the indices into `indices`. The arrays have the sizes gb_xatlas_mesh_counts gave.
void gb_xatlas_mesh_copy(const void *atlas, uint32_t mesh, float *uv, uint32_t *xref,
                         int32_t *atlas_index, uint32_t *indices) {
    const xatlas::Mesh &m = static_cast<const xatlas::Atlas *>(atlas)->meshes[mesh];
    for (uint32_t i = 0; i < m.vertexCount; i++) {
        uv[2 * i] = m.vertexArray[i].uv[0];
        uv[2 * i + 1] = m.vertexArray[i].uv[1];
        xref[i] = m.vertexArray[i].xref;
        atlas_index[i] = m.vertexArray[i].atlasIndex;
    }
    for (uint32_t i = 0; i < m.indexCount; i++) indices[i] = m.indexArray[i];
}

}  // extern "C"
