//! Prints every packet struct's size and field offsets, the schema string and its hash as
//! JSON, for mirrors in other languages to test against (`python/oils_fsw` does):
//! `cargo run -p oils-shared --example layout_json`.

fn main() {
    println!("{}", oils_shared::c_abi::layout_json());
}
