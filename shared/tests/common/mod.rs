pub mod c_build;
