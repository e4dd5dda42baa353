//! Opens the iceoryx2 domain this environment selects, as every Rust participant does
//! (`oils_shared::domain::Domain::from_env`), and prints its root and prefix as JSON, for
//! clients in other languages to test against (`python/tests/test_domain.py` does):
//! `cargo run -p oils-shared --example domain_json`.

/// `s` as a JSON string.
fn json(s: &str) -> String {
    let mut out = String::from("\"");
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c if (c as u32) < 0x20 => out.push_str(&format!("\\u{:04x}", c as u32)),
            c => out.push(c),
        }
    }
    out.push('"');
    out
}

fn main() {
    match oils_shared::domain::Domain::from_env() {
        Ok(d) => println!(
            "{{\"root\":{},\"prefix\":{}}}",
            json(&d.root().to_string_lossy()),
            json(&d.prefix())
        ),
        Err(e) => {
            eprintln!("error: {e}");
            std::process::exit(1);
        }
    }
}
