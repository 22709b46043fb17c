fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let s = scene::load(&a[0]).unwrap();
    let p = scene::export::write_obj_mtl_toml(&s, std::path::Path::new(&a[1])).unwrap();
    let t = scene::load(p.to_str().unwrap()).unwrap();
    println!("{} {}", scene::fingerprint_hex(&s.fingerprint), scene::fingerprint_hex(&t.fingerprint));
}
