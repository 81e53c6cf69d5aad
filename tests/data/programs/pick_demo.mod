MODULE PickDemo
    ! kinecal test module: joint targets in degrees, robtargets left alone
    CONST jointtarget jHome:=[[0,0,0,0,30,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST jointtarget jAbove:=[[12.5,-20.25,35,0.5,45,-90],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    CONST robtarget pPick:=[[600,50,400],[0,0,1,0],[0,0,0,0],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]];
    PROC main()
        MoveAbsJ jHome\NoEOffs, v1000, fine, tool0;
        MoveAbsJ jAbove\NoEOffs, v500, z10, tool0;
        MoveL pPick, v200, fine, tool0;
        MoveAbsJ [[-30,10,20,0,60,15],[9E+09,9E+09,9E+09,9E+09,9E+09,9E+09]]\NoEOffs, v500, fine, tool0;
    ENDPROC
ENDMODULE
