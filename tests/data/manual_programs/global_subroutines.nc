;all global subroutines
%MAIN (main program)
N100 G90 G00 X0 Y0 Z0
N200 L gup_1.nc  ;Direct call of a global subroutine by
                 ;file name if program path is configured
N250 L D:\prog\ini_1.nc  ;Direct call of a global subroutine by
                         ;specifying absolute program path
N300 M30
