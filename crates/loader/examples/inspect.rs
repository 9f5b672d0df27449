//! Print `loader::inspect::inspect(PATH)` as JSON (the library side of
//! `romosplat inspect`): `cargo run -p loader --example inspect -- PATH`.

fn main() {
    let Some(path) = std::env::args().nth(1) else {
        eprintln!("usage: inspect PATH");
        std::process::exit(2);
    };
    match loader::inspect::inspect(&path) {
        Ok(r) => println!("{}", serde_json::to_string_pretty(&r).unwrap_or_default()),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
