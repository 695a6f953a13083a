; robot_start.nc - a start-up subroutine of our own for the 6-axis stand-in machine (tests/data/robot):
; what a robot cell's program start sets before it moves, in the style of ISG's robot examples.
%robot_start
N10 V.E.NC_LOG_PATH_NUMBER = 2
; the transformation only outside teach mode (7)
N20 $IF V.E.HMI_OPERATION_MODE != 7
N21   #TRAFO ON
N22 $ENDIF
; T1 (reduced speed): the path velocity stays below 250 mm/s
N30 $IF V.E.REDUCED_SPEED_ACTIVE == TRUE
N31   #VECTOR LIMIT ON [VEL=12000]
N32 $ELSE
N33   #VECTOR LIMIT OFF [VEL]
N34 $ENDIF
N40 #VECTOR LIMIT ON [ACC=2000000 DEC=2000000]
N50 V.E.NC_LOG_PATH_NUMBER = 1
N60 M17
