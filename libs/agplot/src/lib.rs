//! SVG plots of learned affordance gradients: per alpha S, P, R+ and R- with the object's border, as Fig. 2 of the paper.

#![warn(missing_docs)]

mod colour_map;
mod gradient_plot;

pub use gradient_plot::{PlotError, plot_gradient};
