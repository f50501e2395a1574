// xatlas's charts before packing, for a packer of our own (driver/src/prepare/unwrap/pack.rs).
// This file compiles xatlas itself (it includes vendor/xatlas.cpp) so it can read the
// internal charts that xatlas's public API only hands out packed.
#include "../vendor/xatlas.cpp"

extern "C" {

// After gb_xatlas_compute_charts: per source face of output mesh `mesh` (`face_count` faces),
// the chart it belongs to, numbered from 0 over the mesh's charts (UINT32_MAX for a face in no
// chart: xatlas ignores faces of area <= FLT_EPSILON), and in `face_uv` its three corners'
// (u, v) at one texel per world unit: the chart turned into its least-area bounding box,
// minimum corner at (0, 0), scaled as xatlas's packer scales it (AtlasPacker::packCharts,
// before its chart-size limit and whole-texel stretch). Returns the mesh's chart count.
uint32_t gb_xatlas_chart_uvs(const void *atlas, uint32_t mesh, uint32_t face_count,
                             uint32_t *face_chart, float *face_uv) {
    using namespace xatlas::internal;
    const xatlas::Context *ctx = static_cast<const xatlas::Context *>(atlas);
    for (uint32_t f = 0; f < face_count; f++) {
        face_chart[f] = UINT32_MAX;
        for (uint32_t k = 0; k < 6; k++) face_uv[6 * f + k] = 0.0f;
    }
    if (!ctx->paramAtlas.chartsParameterized() || mesh >= ctx->paramAtlas.meshCount()) return 0;
    uint32_t chartIndex = 0;
    for (uint32_t g = 0; g < ctx->paramAtlas.chartGroupCount(mesh); g++) {
        const param::ChartGroup *group = ctx->paramAtlas.chartGroupAt(mesh, g);
        if (group->isVertexMap()) continue;
        for (uint32_t c = 0; c < group->chartCount(); c++, chartIndex++) {
            const param::Chart *chart = group->chartAt(c);
            const Mesh *cm = chart->mesh();
            const float area = chart->computeSurfaceArea();
            float parametricArea = chart->computeParametricArea();
            if (parametricArea < kEpsilon) {
                const Vector2 bounds = chart->computeParametricBounds();
                parametricArea = bounds.x * bounds.y;
            }
            const float scale = parametricArea == 0.0f ? 0.0f : area / parametricArea;
            Vector2 major, minor, origin, end;
            param::AtlasPacker::exportBoundingBox(chart, &major, &minor, &origin, &end);
            for (uint32_t f = 0; f < cm->faceCount(); f++) {
                const Face *face = cm->faceAt(f);
                const uint32_t source = group->mapFaceToSourceFace(chart->mapFaceToSourceFace(f));
                if (source >= face_count || face->nIndices != 3) continue;
                face_chart[source] = chartIndex;
                for (uint32_t j = 0; j < 3; j++) {
                    const Vector2 &t = cm->texcoord(cm->vertexAt(face->firstIndex + j));
                    face_uv[6 * source + 2 * j] = (dot(t, major) - origin.x) * scale;
                    face_uv[6 * source + 2 * j + 1] = (dot(t, minor) - origin.y) * scale;
                }
            }
        }
    }
    return chartIndex;
}

}  // extern "C"
