// Composition of the CPU floating-horizon raycast (Szenberg 1997, ch. 8):
// its colour and its depth — the GPU projection's depth by construction,
// eq. 5.11 — are written into the shared colour and depth targets, so
// objects drawn afterwards are hidden exactly where the terrain covers them.
// A terrain-only frame uses `fs_colour` and skips the depth upload
// (table 8.1).

// Both are in the raycaster's column tiles: one tile per layer.
@group(0) @binding(0) var colour: texture_2d_array<f32>;
@group(0) @binding(1) var depth: texture_2d_array<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // One triangle covering the screen.
    let corner = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(corner * 2.0 - 1.0, 0.0, 1.0);
}

struct WithDepth {
    @location(0) colour: vec4<f32>,
    @builtin(frag_depth) depth: f32,
};

// Pixel `p` of the screen: its column within its tile, its row, its tile.
struct Texel {
    at: vec2<i32>,
    tile: i32,
};

fn texel(p: vec4<f32>) -> Texel {
    let pixel = vec2<i32>(p.xy);
    let columns = i32(textureDimensions(colour).x);
    return Texel(vec2<i32>(pixel.x % columns, pixel.y), pixel.x / columns);
}

@fragment
fn fs_colour_and_depth(@builtin(position) p: vec4<f32>) -> WithDepth {
    let t = texel(p);
    var out: WithDepth;
    out.colour = textureLoad(colour, t.at, t.tile, 0);
    out.depth = textureLoad(depth, t.at, t.tile, 0).r;
    return out;
}

@fragment
fn fs_colour(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let t = texel(p);
    return textureLoad(colour, t.at, t.tile, 0);
}
