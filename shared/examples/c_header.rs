//! Prints `shared/include/oils.h`, generated from the Rust packet definitions:
//! `cargo run -p oils-shared --example c_header > shared/include/oils.h`.

fn main() {
    print!("{}", oils_shared::c_abi::c_header());
}
