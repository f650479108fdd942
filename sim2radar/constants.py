"""Physical constants, in SI units. One line of comment each."""

SPEED_OF_LIGHT_M_S = 299_792_458.0  # speed of light in vacuum [m/s] (exact, SI 2019)
VACUUM_PERMITTIVITY_F_M = 8.8541878128e-12  # electric constant eps0 [F/m] (CODATA 2018)
VACUUM_PERMEABILITY_H_M = 1.25663706212e-6  # magnetic constant mu0 [H/m] (CODATA 2018)
BOLTZMANN_J_K = 1.380649e-23  # Boltzmann constant [J/K] (exact, SI 2019)
REFERENCE_TEMPERATURE_K = 290.0  # standard noise temperature T0 [K] (IEEE Std 145)
