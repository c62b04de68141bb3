unit Graphics;

{ Only the LCL system-colour constants PascalScript's uPSC_graphics (compile-time side) reads from
  Graphics: SimTwo is built with the LCL, whose values are SYS_COLOR_BASE or the Windows COLOR_*
  index. Nothing else of the LCL is needed to compile scripts, and none of it is needed to run
  simtwo/control.pas, so the harness does not build the LCL. }

{$mode delphi}

interface

const
  SYS_COLOR_BASE = -2147483647 - 1;   // $80000000 as an Integer (TColor)
  clScrollBar = SYS_COLOR_BASE + 0;
  clBackground = SYS_COLOR_BASE + 1;
  clActiveCaption = SYS_COLOR_BASE + 2;
  clInactiveCaption = SYS_COLOR_BASE + 3;
  clMenu = SYS_COLOR_BASE + 4;
  clWindow = SYS_COLOR_BASE + 5;
  clWindowFrame = SYS_COLOR_BASE + 6;
  clMenuText = SYS_COLOR_BASE + 7;
  clWindowText = SYS_COLOR_BASE + 8;
  clCaptionText = SYS_COLOR_BASE + 9;
  clActiveBorder = SYS_COLOR_BASE + 10;
  clInactiveBorder = SYS_COLOR_BASE + 11;
  clAppWorkspace = SYS_COLOR_BASE + 12;
  clHighlight = SYS_COLOR_BASE + 13;
  clHighlightText = SYS_COLOR_BASE + 14;
  clBtnFace = SYS_COLOR_BASE + 15;
  clBtnShadow = SYS_COLOR_BASE + 16;
  clGrayText = SYS_COLOR_BASE + 17;
  clBtnText = SYS_COLOR_BASE + 18;
  clInactiveCaptionText = SYS_COLOR_BASE + 19;
  clBtnHighlight = SYS_COLOR_BASE + 20;
  cl3DDkShadow = SYS_COLOR_BASE + 21;
  cl3DLight = SYS_COLOR_BASE + 22;
  clInfoText = SYS_COLOR_BASE + 23;
  clInfoBk = SYS_COLOR_BASE + 24;

implementation

end.
