// Gouraud drawing of the triangle table with tone mapping (DESIGN.md §2, §9; thesis §2.3, §4.1).
// Vertex radiances are exact GI samples; the rasteriser interpolates them across each triangle and
// every fragment is tone-mapped on its luminance, keeping its colour.

struct Uniforms {
    view_proj: mat4x4<f32>,
    l_white: f32,
    // 0: linear radiance out (EXR snapshots), 1: Drago (eq. 4.2), 2: Reinhard (eq. 4.1).
    mode: u32,
    wireframe: u32,
    // 1 when the target is not an sRGB format and the shader must encode itself.
    encode_srgb: u32,
    // The eye ray through normalised device coordinates (x, y) is
    // forward + x * right + y * up (right and up scaled by the half field of view).
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    // Sky radiance over the upper hemisphere (+Y), black below the horizon (DESIGN.md §7).
    sky: vec4<f32>,
    // Unit direction toward the sun; w: 1 - cos of the disc's angular radius (0: no sun).
    sun_dir: vec4<f32>,
    sun_radiance: vec4<f32>,
    // 1 when `direct_tiles` holds per-pixel direct light of this picture (DESIGN.md §3 step 8).
    tiles: u32,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
// Per pixel the direct part of a resting camera's tiles, alpha 1 where it is shown (direct_image.rs).
@group(1) @binding(0) var direct_tiles: texture_2d<f32>;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) radiance: vec3<f32>,
    // Barycentric coordinates, for the wireframe overlay: the vertex index within its triangle.
    @location(1) bary: vec3<f32>,
    // Clip z and w, for the depth each fragment writes itself: wgpu's GL backend remaps clip z to
    // GL's -1..1 before the fixed function divides by w, which loses the precision reversed Z
    // keeps far from the eye; a fragment's own z / w is the same on every backend.
    @location(2) zw: vec2<f32>,
    // `radiance` less its direct part (albedo × direct illumination): interpolated on its own,
    // as the product of an interpolated share and an interpolated sum is not the interpolated
    // rest (across a shadow edge it would carry the lit side's direct light into the shadow).
    @location(3) rest: vec3<f32>,
};

struct FragmentOut {
    @builtin(frag_depth) depth: f32,
    @location(0) colour: vec4<f32>,
};

@vertex
fn vs_main(
    @builtin(vertex_index) index: u32,
    @location(0) position: vec3<f32>,
    @location(1) radiance: vec3<f32>,
    @location(2) direct_share: f32,
) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.zw = out.clip.zw;
    out.radiance = radiance;
    out.rest = radiance * (1.0 - direct_share);
    let k = index % 3u;
    out.bary = vec3<f32>(f32(k == 0u), f32(k == 1u), f32(k == 2u));
    return out;
}

const REC709 = vec3<f32>(0.2126, 0.7152, 0.0722);

fn display_luminance(l: f32) -> f32 {
    let lw = u.l_white;
    if u.mode == 2u {
        return l * (1.0 + l / (lw * lw)) / (1.0 + l);
    }
    return log(1.0 + l) / log(1.0 + lw);
}

fn tone_map(rgb: vec3<f32>) -> vec3<f32> {
    let l = dot(rgb, REC709);
    if l <= 0.0 {
        return vec3<f32>(0.0);
    }
    return clamp(rgb * (display_luminance(l) / l), vec3<f32>(0.0), vec3<f32>(1.0));
}

fn srgb_encode(c: vec3<f32>) -> vec3<f32> {
    let low = c * 12.92;
    let high = 1.055 * pow(c, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(high, low, c <= vec3<f32>(0.0031308));
}

// The sky: one triangle over the whole target, drawn first without depth, so geometry covers it.
// Its alpha is 0 in the linear image: the snapshot's coverage (pixels that see no geometry).
struct SkyOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) ndc: vec2<f32>,
};

@vertex
fn vs_sky(@builtin(vertex_index) index: u32) -> SkyOut {
    let ndc = vec2<f32>(f32(index == 1u) * 4.0 - 1.0, f32(index == 2u) * 4.0 - 1.0);
    return SkyOut(vec4<f32>(ndc, 0.0, 1.0), ndc);
}

// Like the renderer's sky and sun: nothing from below the horizon (DESIGN.md §7).
fn sky_radiance(dir: vec3<f32>) -> vec3<f32> {
    var radiance = select(vec3<f32>(0.0), u.sky.xyz, dir.y > 0.0);
    if u.sun_dir.w > 0.0 && dir.y > 0.0 && 1.0 - dot(dir, u.sun_dir.xyz) <= u.sun_dir.w {
        radiance += u.sun_radiance.xyz;
    }
    return radiance;
}

@fragment
fn fs_sky(in: SkyOut) -> @location(0) vec4<f32> {
    let dir = normalize(u.forward.xyz + in.ndc.x * u.right.xyz + in.ndc.y * u.up.xyz);
    let radiance = sky_radiance(dir);
    if u.mode == 0u {
        return vec4<f32>(radiance, 0.0);
    }
    return vec4<f32>(display(tone_map(radiance)), 1.0);
}

fn display(colour: vec3<f32>) -> vec3<f32> {
    if u.encode_srgb == 1u {
        return srgb_encode(colour);
    }
    return colour;
}

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    return FragmentOut(in.zw.x / in.zw.y, shade(in));
}

// Where a tile's pixel is shown: its direct part plus the interpolated rest (indirect and
// view-dependent), the vertices' radiance less their direct share (DESIGN.md §3 step 8).
fn with_direct_tiles(in: VertexOut) -> vec3<f32> {
    if u.tiles == 0u {
        return in.radiance;
    }
    let texel = textureLoad(direct_tiles, vec2<i32>(in.clip.xy), 0);
    if texel.a < 0.5 {
        return in.radiance;
    }
    return texel.rgb + in.rest;
}

fn shade(in: VertexOut) -> vec4<f32> {
    // Derivatives first, in uniform control flow.
    let edge = min(in.bary.x, min(in.bary.y, in.bary.z));
    let edge_width = fwidth(edge);
    let radiance = with_direct_tiles(in);
    if u.mode == 0u {
        return vec4<f32>(radiance, 1.0);
    }
    var colour = tone_map(radiance);
    if u.wireframe == 1u {
        let line = 1.0 - smoothstep(0.0, 1.5 * edge_width, edge);
        colour = mix(colour, vec3<f32>(0.1, 0.9, 0.3), 0.8 * line);
    }
    return vec4<f32>(display(colour), 1.0);
}
