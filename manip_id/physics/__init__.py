"""Physics of the parameters: physical consistency, perturbation and repair of bodies."""
