%G807_delays
(stand-in: G807[mode, start, stop] keeps the dispensing delays for the PLC; G807 alone switches them off)
N10 $IF EXIST[@P1]
N20   V.E.DELAYS[0] = @P1
N30   $IF EXIST[@P2]
N40     V.E.DELAYS[1] = @P2
N50   $ENDIF
N60   $IF EXIST[@P3]
N70     V.E.DELAYS[2] = @P3
N80   $ENDIF
N90 $ELSE
N100  V.E.DELAYS[0] = 0
N110 $ENDIF
N120 M17
