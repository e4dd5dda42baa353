//! The world around the lander that is not the lander: the terrain about the landing
//! site (the rotating Moon and its frames live in the plant).

pub mod terrain;
