"""The candidate effects: their regressors, their physics in the simulation, the library."""
