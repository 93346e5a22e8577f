"""NumPy references: the definition of what each kernel computes.

Each module mirrors the family module of the same name, function for function
with the same arguments. Written to be obviously right, never called by the
library; the tests compare the kernels to them.
"""
