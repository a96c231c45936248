"""The physics: field, elastomer mechanics, predictions, calibration and acceptance models (numpy/scipy/scikit-fem;
values in, values out)."""
