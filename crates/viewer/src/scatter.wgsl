// Scatters changed triangles into the vertex buffer (vertex_buffer.rs): removals and recolours hit
// random slots, and one dispatch over a packed list of (slot, 36 words) is far cheaper than a
// buffer write per slot.

struct Params {
    count: u32,
    // Invocations per row of workgroups (a batch can exceed 65535 workgroups in one dimension).
    row: u32,
};

// Words of one triangle: 3 vertices × (position, illumination, direct share, view-dependent
// radiance, texture coordinates, surface), 12 words each, as `table::Vertex`.
const TRIANGLE_WORDS: u32 = 36u;
const WORDS: u32 = 37u; // slot + the triangle

@group(0) @binding(0) var<storage, read> patches: array<u32>;
@group(0) @binding(1) var<storage, read_write> vertices: array<u32>;
@group(0) @binding(2) var<uniform> params: Params;

@compute @workgroup_size(64)
fn scatter(@builtin(global_invocation_id) id: vec3<u32>) {
    let i = id.x + id.y * params.row;
    if i >= params.count {
        return;
    }
    let source = i * WORDS;
    let to = patches[source] * TRIANGLE_WORDS;
    for (var k = 0u; k < TRIANGLE_WORDS; k++) {
        vertices[to + k] = patches[source + 1u + k];
    }
}
