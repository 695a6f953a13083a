%L UP1           (1st local subroutine)
N1 G01 X10 F1000
N9 M17           (M17 can also be left out)
%L UP2           (2nd local subroutine)
N11 G01 Y10 F1000
N19 M29           (M29 can also be left out)
%MAIN            (main program)
N100 G90 G00 X0 Y0 Z0
N200 LL UP1      (Call 1st LSUB)
N250 LL UP2      (Call 2nd LSUB)
N300 M30         (Main program end)
