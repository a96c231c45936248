"""Unit conversion constants, defined here and nowhere else.

Geometry is in millimetres (CadQuery's and KiCad's unit), physics in SI inside the models; field values
that reach a user are in gauss (the paper's unit) or microtesla (the chip's). Multiply a value in the
unit on the right of ``_PER_`` to get the unit on the left: ``b_G = b_T * GAUSS_PER_TESLA``.
"""

GAUSS_PER_TESLA = 1.0e4
UT_PER_GAUSS = 100.0  # 1 G = 100 uT
G0 = 9.80665  # m/s^2, standard gravity (CGPM 1901): a weight of W grams pushes with W * G0 / 1000 N
GAUSS_PER_MT = 10.0  # 1 mT = 10 G
UT_PER_TESLA = 1.0e6
MM_PER_M = 1.0e3
M_PER_MM = 1.0e-3
MM2_PER_M2 = 1.0e6
PA_PER_KPA = 1.0e3
MN_PER_N = 1.0e3  # millinewtons per newton
N_PER_KPA_MM2 = PA_PER_KPA / MM2_PER_M2  # a stress in kPa over an area in mm^2 gives newtons
US_PER_S = 1.0e6
MS_PER_S = 1.0e3
