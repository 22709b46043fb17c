// Gouraud drawing of the triangle table with tone mapping (DESIGN.md §2, §9; thesis §2.3, §4.1).
// Vertex illumination is exact GI samples; the rasteriser interpolates it across each triangle,
// every fragment multiplies it by its own albedo, the material's factor times its texture's texel
// (DESIGN.md §5, "Parts, and textures"), adds the view-dependent radiance, and is tone-mapped on
// its luminance, keeping its colour.

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
// Per pixel the direct part of a resting camera's tiles, alpha the standard error of its
// luminance, negative where no tile has covered the pixel (direct_image.rs).
@group(1) @binding(0) var direct_tiles: texture_2d<f32>;
// Per material (looks_texture.rs): the factor the texel multiplies, and the texture array layer
// (0: white), negated where the texture clamps.
@group(2) @binding(0) var materials: texture_2d<f32>;
@group(2) @binding(1) var albedo_maps: texture_2d_array<f32>;
@group(2) @binding(2) var albedo_sampler: sampler;

const MATERIALS_PER_ROW: u32 = 256u;
const CLAMPS: u32 = 0x80000000u;

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) illumination: vec3<f32>,
    // Barycentric coordinates, for the wireframe overlay: the vertex index within its triangle.
    @location(1) bary: vec3<f32>,
    // Clip z and w, for the depth each fragment writes itself: wgpu's GL backend remaps clip z to
    // GL's -1..1 before the fixed function divides by w, which loses the precision reversed Z
    // keeps far from the eye; a fragment's own z / w is the same on every backend.
    @location(2) zw: vec2<f32>,
    // `illumination` less its direct part: interpolated on its own, as the product of an
    // interpolated share and an interpolated sum is not the interpolated rest (across a shadow
    // edge it would carry the lit side's direct light into the shadow).
    @location(3) rest: vec3<f32>,
    @location(4) view_dependent: vec3<f32>,
    @location(5) uv: vec2<f32>,
    // The material's factor, and its layer with CLAMPS set where the texture clamps.
    @location(6) factor: vec3<f32>,
    @location(7) @interpolate(flat) layer: u32,
};

struct FragmentOut {
    @builtin(frag_depth) depth: f32,
    @location(0) colour: vec4<f32>,
};

@vertex
fn vs_main(
    @builtin(vertex_index) index: u32,
    @location(0) position: vec3<f32>,
    @location(1) illumination: vec3<f32>,
    @location(2) direct_share: f32,
    @location(3) view_dependent: vec3<f32>,
    @location(4) texcoord: vec2<u32>,
    @location(5) surface: u32,
) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.zw = out.clip.zw;
    out.illumination = illumination;
    out.rest = illumination * (1.0 - direct_share);
    out.view_dependent = view_dependent;
    // protocol::texture::Texcoords: 16-bit steps over 0..2^range.
    let range = min((surface >> 16u) & 0xffu, 15u);
    out.uv = vec2<f32>(texcoord) * (exp2(f32(range)) / 65536.0);
    let material = surface & 0xffffu;
    let at = vec2<u32>(material % MATERIALS_PER_ROW, material / MATERIALS_PER_ROW);
    var look = vec4<f32>(1.0, 1.0, 1.0, 0.0);
    if at.y < textureDimensions(materials).y {
        look = textureLoad(materials, at, 0);
    }
    out.factor = look.rgb;
    out.layer = u32(abs(look.a) + 0.5) | select(0u, CLAMPS, look.a < 0.0);
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

// The albedo of this fragment: the material's factor times its texel, sampled trilinearly (OBJ's
// v grows up the image, the texture's rows go down). A clamped texture holds its edge texels.
fn albedo(in: VertexOut) -> vec3<f32> {
    let layer = in.layer & ~CLAMPS;
    let size = vec2<f32>(textureDimensions(albedo_maps));
    let edge = 0.5 / size;
    let clamped = clamp(in.uv, edge, vec2<f32>(1.0) - edge);
    let uv = select(in.uv, clamped, (in.layer & CLAMPS) != 0u);
    let texel = textureSample(albedo_maps, albedo_sampler, vec2<f32>(uv.x, 1.0 - uv.y), layer);
    return in.factor * texel.rgb;
}

// A tile's pixel stands in for the vertices' direct part (DESIGN.md §3 step 8) where it is the
// better estimate. Two tests, both by the tile's own standard error `sigma` of its luminance:
// - quiet: `sigma` is a small fraction of the whole pixel's luminance, below what tone-mapped
//   noise shows; a pixel in full sun or full shadow (no variance) passes from its first pass;
// - biased: the vertices' interpolated direct part differs from the tile by more than the tile's
//   noise explains, as at a shadow edge the mesh does not resolve, so the interpolation is wrong
//   there whatever its own noise (the criteria's noise test, DESIGN.md §6, per pixel).
// Elsewhere the smooth vertex picture is kept: a few paths' per-pixel noise would show as grain
// where the interpolated estimate is already right. Both tests ramp over a range, so a pixel
// crosses over without a seam as passes accumulate.
const TILE_PRECISE_FROM: f32 = 0.03;
const TILE_PRECISE_AT: f32 = 0.015;
const TILE_BIASED_FROM: f32 = 5.0;
const TILE_BIASED_AT: f32 = 8.0;

fn tile_weight(tile: vec3<f32>, sigma: f32, vertices: vec3<f32>, whole: vec3<f32>) -> f32 {
    if sigma < 0.0 {
        return 0.0;
    }
    let relative = sigma / max(dot(whole, REC709), 1e-6);
    let quiet = 1.0 - smoothstep(TILE_PRECISE_AT, TILE_PRECISE_FROM, relative);
    let apart = abs(dot(tile - vertices, REC709)) / max(sigma, 1e-6);
    let biased = smoothstep(TILE_BIASED_FROM, TILE_BIASED_AT, apart);
    return max(quiet, biased);
}

// The radiance of this fragment: albedo × interpolated illumination + view-dependent part, or
// where a tile's pixel stands in (`tile_weight`), its direct part (radiance with the renderer's
// albedo of that pixel) plus the interpolated rest (indirect illumination) times this albedo and
// the view-dependent part.
fn radiance_of(in: VertexOut, albedo: vec3<f32>) -> vec3<f32> {
    let whole = albedo * in.illumination + in.view_dependent;
    if u.tiles == 0u {
        return whole;
    }
    let texel = textureLoad(direct_tiles, vec2<i32>(in.clip.xy), 0);
    let rest = albedo * in.rest + in.view_dependent;
    let tiled = texel.rgb + rest;
    let weight = tile_weight(texel.rgb, texel.a, whole - rest, tiled);
    return mix(whole, tiled, weight);
}

fn shade(in: VertexOut) -> vec4<f32> {
    // Derivatives (and the implicit ones of the texture's sample) first, in uniform control flow.
    let edge = min(in.bary.x, min(in.bary.y, in.bary.z));
    let edge_width = fwidth(edge);
    let radiance = radiance_of(in, albedo(in));
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
