%G805_set_origin
(stand-in: G805[x, y, z] keeps the work origin for the PLC; the zero offsets are the machine file's)
N10 V.E.ORIGIN[0] = @P1
N20 V.E.ORIGIN[1] = @P2
N30 V.E.ORIGIN[2] = @P3
N40 M17
