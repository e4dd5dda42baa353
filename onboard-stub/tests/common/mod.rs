#[path = "../../../shared/tests/common/c_build.rs"]
pub mod c_build;
