use protocol::renderer_link::*;
use protocol::Side;
use renderer::*;
fn main() {
    for (spec, views) in [("scenes/sponza.toml", vec!["S1", "S2", "S3"]), ("bracara", vec!["MC", "VR", "VT"])] {
    let world = World::new(scene::load(spec).unwrap());
    for view in views {
    let cam = renderer::reference::camera_for(&world, view, 160, 120).unwrap();
    let (mut n, mut moved, mut probes) = (0, 0, 0u64);
    for y in 0..120 { for x in 0..160 {
        let dir = cam.ray_direction(x as f32 + 0.5, y as f32 + 0.5);
        let Some(hit) = world.bvh.closest_hit(cam.eye_vec(), dir, f32::INFINITY) else { continue };
        let s = world.surface_at(cam.eye_vec(), dir, hit);
        let mut c = RayCounts::default();
        n += 1;
        if renderer::point::is_hidden(&world, &s, &mut c) { moved += 1; if moved < 4 { println!("  visible-but-hidden at {} n={} px {x},{y}", s.position, s.normal); } }
        probes += c.probe;
    }}
    println!("{spec} {view}: {n} visible points, {moved} judged hidden, {:.1} probes/point", probes as f64 / n as f64);
    }}
}
