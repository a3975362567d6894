// The refined mesh: positions relative to the eye (f32 keeps centimetres
// however large the terrain), the drape as texture or a height ramp with
// Lambert shading, and a barycentric wireframe overlay.

struct Uniforms {
    // Off-axis projection × view, eye at the origin (relevo-core's Camera).
    view_proj: mat4x4<f32>,
    // xyz: unit vector towards the sun (terrain frame); w: ambient light.
    sun: vec4<f32>,
    // x: 1 draws the drape; y: 1 overlays the wireframe;
    // z: lowest height (m); w: 1 / height range (1/m).
    options: vec4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var drape: texture_2d_array<f32>;
@group(0) @binding(2) var drape_sampler: sampler;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) normal: vec3<f32>,
    @location(3) barycentric: vec3<f32>,
    @location(4) height: f32,
    // The drape's layer: 0 for a single grid, the tile's for a pyramid.
    @location(5) layer: u32,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) barycentric: vec3<f32>,
    @location(3) height: f32,
    @location(4) @interpolate(flat) layer: u32,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = u.view_proj * vec4<f32>(v.position, 1.0);
    out.uv = v.uv;
    out.normal = v.normal;
    out.barycentric = v.barycentric;
    out.height = v.height;
    out.layer = v.layer;
    return out;
}

@fragment
fn fs_main(v: VertexOut) -> @location(0) vec4<f32> {
    let texel = textureSample(drape, drape_sampler, v.uv, v.layer).rgb;
    let t = clamp((v.height - u.options.z) * u.options.w, 0.0, 1.0);
    let ramp = mix(vec3<f32>(0.32, 0.42, 0.26), vec3<f32>(0.92, 0.90, 0.84), t);
    let light = u.sun.w + (1.0 - u.sun.w) * max(dot(normalize(v.normal), u.sun.xyz), 0.0);
    var colour = select(ramp * light, texel, u.options.x > 0.5);
    let edge_distance = min(min(v.barycentric.x, v.barycentric.y), v.barycentric.z);
    let edge = 1.0 - smoothstep(0.0, 1.5 * fwidth(edge_distance), edge_distance);
    colour = mix(colour, vec3<f32>(0.08, 0.08, 0.08), 0.8 * edge * u.options.y);
    return vec4<f32>(colour, 1.0);
}
