//! Cross-crate and property tests of streamcert: one test binary, one module per topic.

mod affine;
mod ambiguity;
mod anchored;
mod calibrated;
mod calibrated_config;
mod certificate;
mod change;
mod checkpoint;
mod coefficient_covariance;
mod compose;
mod crate_graph;
mod dynamics;
mod identification;
mod ladder;
mod module_graph;
mod network;
mod network_coupling;
mod nonlinear;
mod nonlinear_bound;
mod nonlinear_region;
mod order;
mod packages;
mod regression;
mod reliability;
mod support;
