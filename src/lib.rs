//! dofray: depth-of-field rendering on Intel Embree.
//!
//! The renderer traces 16-wide packets of thin-lens rays only at adaptive sample sites, dense
//! where the image is in focus and sparse where it is blurred, and interpolates between them
//! (Kumamoto, "A Faster Technique for Rendering Depth of Field Images").

pub mod embree;
