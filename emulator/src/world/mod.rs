//! The world around the lander that is not the lander: the terrain about the landing
//! site and the sun's direction there (the rotating Moon and its frames live in the
//! plant).

pub mod sun;
pub mod terrain;
