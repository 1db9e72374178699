//! Soil-tool force models (under construction).
