// Vegetation impostors from relevo-core's cut (vegetation thesis, ch. 4):
// side views as billboards turned about the vertical to face the eye, top
// views as horizontal shell textures, both depth-tested against whatever
// the terrain wrote (the mesh's depth or the raycast's uploaded depth).
// Texels are premultiplied; a fragment is kept when its coverage passes
// 50 % and the pixel's ordered-dither threshold falls in the view's share
// of the cross-fade, so two views fading into each other split the pixels
// between them without sorting.

struct Uniforms {
    view_proj: mat4x4<f32>,
    // x: 1 when impostors are cut out by their alpha.
    flags: vec4<u32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var atlas: texture_2d_array<f32>;
@group(0) @binding(2) var atlas_sampler: sampler;

struct Instance {
    // Foot relative to the eye (metres); kind 0 = side view, 1 = top view,
    // 2 and 3 = sprite planes along x (front view) and y (left view).
    @location(0) foot: vec3<f32>,
    @location(1) kind: u32,
    // Unit horizontal vector towards the eye; width and height (metres).
    @location(2) facing: vec2<f32>,
    @location(3) size: vec2<f32>,
    // Height of the top view above the foot; the dither share [from, to).
    @location(4) top: f32,
    @location(5) share: vec2<f32>,
    // Atlas rectangle (u0, v0, u1, v1) and page.
    @location(6) uv: vec4<f32>,
    @location(7) page: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) @interpolate(flat) page: u32,
    @location(2) share: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) corner: u32, i: Instance) -> VertexOut {
    // Triangle strip: (0, 0), (1, 0), (0, 1), (1, 1); t up the image.
    let s = f32(corner & 1u);
    let t = f32(corner >> 1u);
    var position: vec3<f32>;
    if i.kind != 1u {
        // A side view's right: the eye's right for a billboard (the facing
        // vector turned a quarter clockwise), east for the front plane and
        // south for the left plane of a sprite (the views' own rights).
        var right = vec3<f32>(-i.facing.y, i.facing.x, 0.0);
        if i.kind == 2u {
            right = vec3<f32>(1.0, 0.0, 0.0);
        } else if i.kind == 3u {
            right = vec3<f32>(0.0, -1.0, 0.0);
        }
        position = i.foot + right * ((s - 0.5) * i.size.x) + vec3<f32>(0.0, 0.0, t * i.size.y);
    } else {
        // Top view: image up is north.
        position = i.foot + vec3<f32>((s - 0.5) * i.size.x, (t - 0.5) * i.size.y, i.top);
    }
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(position, 1.0);
    out.uv = vec2<f32>(mix(i.uv.x, i.uv.z, s), mix(i.uv.w, i.uv.y, t));
    out.page = i.page;
    out.share = i.share;
    return out;
}

// 4×4 ordered-dither thresholds in [0, 1) (Bayer).
fn dither(pixel: vec2<u32>) -> f32 {
    let bayer = array<u32, 16>(0u, 8u, 2u, 10u, 12u, 4u, 14u, 6u, 3u, 11u, 1u, 9u, 15u, 7u, 13u, 5u);
    return (f32(bayer[(pixel.y % 4u) * 4u + pixel.x % 4u]) + 0.5) / 16.0;
}

@fragment
fn fs_main(v: VertexOut) -> @location(0) vec4<f32> {
    let texel = textureSample(atlas, atlas_sampler, v.uv, v.page);
    let threshold = dither(vec2<u32>(v.clip.xy));
    let cut_out = u.flags.x == 1u && texel.a < 0.5;
    if cut_out || threshold < v.share.x || threshold >= v.share.y {
        discard;
    }
    if u.flags.x == 0u {
        // Without alpha the whole quad shows, empty texels black.
        return vec4<f32>(texel.rgb, 1.0);
    }
    return vec4<f32>(texel.rgb / texel.a, 1.0);
}
