pub mod cloud;
pub mod image;
pub mod livox;
