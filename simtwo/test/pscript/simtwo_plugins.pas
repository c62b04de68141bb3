unit simtwo_plugins;

{ The PascalScript plugins SimTwo's script editor uses, in SimTwo's order, for pscript_harness.

  SimTwo (github.com/P33a/SimTwo, Editor.lfm lines 1057-1080 and Editor.pas TFEditor.FormCreate lines
  465-475) plugs into its TPSScriptDebugger, in this order:
    PSImport_Classes   (EnableStreams, EnableClasses)     PascalScript's uPSComponent_Default
    PSImport_Controls  (EnableStreams, Graphics, Controls) uPSComponent_Controls
    PSImport_StdCtrls  (EnableExtCtrls, EnableButtons)     uPSComponent_StdCtrls
    PSImport_Forms     (EnableForms, EnableMenus)          uPSComponent_Forms
    TPSImport_dynmatrix, TPSImport_ODERobotsPublished, TPSImport_PathFinder, TPSImport_user_charts
                                                           SimTwo's uPSI_*.pas
  The compile-time side of each is registered here exactly as those plugins do it (the same
  SIRegister_* calls of PascalScript's uPSC_* units; SimTwo's declarations from simtwo_decls.inc), so
  the compiler accepts and rejects the same scripts as SimTwo's.

  The run-time side differs on purpose: PascalScript's run-time imports of Graphics, Controls, StdCtrls
  and Forms need the LCL and a GUI, and SimTwo's routines need SimTwo. Only RIRegister_Std and
  RIRegister_Classes are registered, plus the stand-in routines of simtwo_api.pas (the ones
  simtwo/control.pas calls). A script that calls anything else compiles as in SimTwo but fails to load
  here with PascalScript's "Unknown procedure" error: the harness never pretends to run what it lacks. }

{$mode delphi}{$H+}

interface

uses
  SysUtils, Classes, uPSComponent, uPSCompiler, uPSRuntime;

type
  TRafImport_Classes = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
    procedure ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter); override;
  end;

  TRafImport_Controls = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
  end;

  TRafImport_StdCtrls = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
  end;

  TRafImport_Forms = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
  end;

  TRafImport_dynmatrix = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
    procedure ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter); override;
  end;

  TRafImport_ODERobotsPublished = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
    procedure ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter); override;
  end;

  TRafImport_PathFinder = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
  end;

  TRafImport_user_charts = class(TPSPlugin)
  protected
    procedure CompileImport1(CompExec: TPSScript); override;
  end;

{ Adds the eight plugins to Script in SimTwo's order. }
procedure AddSimTwoPlugins(Script: TPSScript; Owner: TComponent);

implementation

uses
  uPSC_std, uPSR_std, uPSC_classes, uPSR_classes, uPSC_graphics, uPSC_controls, uPSC_stdctrls,
  uPSC_extctrls, uPSC_buttons, uPSC_forms, uPSC_menus, simtwo_api;

procedure AddFunc(CL: TPSPascalCompiler; const Decl: string);
begin
  if CL.AddDelphiFunction(Decl) = nil then
    raise Exception.Create('PascalScript refused the declaration ' + Decl);
end;

procedure AddType(CL: TPSPascalCompiler; const Name, Decl: string);
begin
  CL.AddTypeS(Name, Decl);
end;

procedure AddConst(CL: TPSPascalCompiler; const Name, Typ: string; Value: Int64; Unsigned: boolean);
begin
  if Unsigned then CL.AddConstantN(Name, Typ).SetUInt(Value)
  else CL.AddConstantN(Name, Typ).SetInt(Value);
end;

{$I simtwo_decls.inc}

{ ---- PascalScript's own plugins, as SimTwo's Editor.lfm configures them ---- }

procedure TRafImport_Classes.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_Std(CompExec.Comp);
  SIRegister_Classes(CompExec.Comp, True);
end;

procedure TRafImport_Classes.ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter);
begin
  RIRegister_Std(ri);
  RIRegister_Classes(ri, True);
end;

procedure TRafImport_Controls.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_Graphics(CompExec.Comp, True);
  SIRegister_Controls(CompExec.Comp);
end;

procedure TRafImport_StdCtrls.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_stdctrls(CompExec.Comp);
  SIRegister_ExtCtrls(CompExec.Comp);
  SIRegister_Buttons(CompExec.Comp);
end;

procedure TRafImport_Forms.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_Forms(CompExec.Comp);
  SIRegister_Menus(CompExec.Comp);
end;

{ ---- SimTwo's import units ---- }

procedure TRafImport_dynmatrix.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_dynmatrix(CompExec.Comp);
end;

procedure TRafImport_dynmatrix.ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter);
begin
  with CompExec.Exec do begin
    RegisterDelphiFunction(@MNumCols, 'MNumCols', cdRegister);
    RegisterDelphiFunction(@MNumRows, 'MNumRows', cdRegister);
    RegisterDelphiFunction(@Mgetv, 'Mgetv', cdRegister);
  end;
end;

procedure TRafImport_ODERobotsPublished.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_ODERobotsPublished(CompExec.Comp);
end;

procedure TRafImport_ODERobotsPublished.ExecImport1(CompExec: TPSScript; const ri: TPSRuntimeClassImporter);
begin
  with CompExec.Exec do begin
    RegisterDelphiFunction(@GetRobotIndex, 'GetRobotIndex', cdRegister);
    RegisterDelphiFunction(@GetAxisIndex, 'GetAxisIndex', cdRegister);
    RegisterDelphiFunction(@GetSensorIndex, 'GetSensorIndex', cdRegister);
    RegisterDelphiFunction(@GetAxisOdo, 'GetAxisOdo', cdRegister);
    RegisterDelphiFunction(@GetRobotX, 'GetRobotX', cdRegister);
    RegisterDelphiFunction(@GetRobotY, 'GetRobotY', cdRegister);
    RegisterDelphiFunction(@GetRobotTheta, 'GetRobotTheta', cdRegister);
    RegisterDelphiFunction(@GetSensorVal, 'GetSensorVal', cdRegister);
    RegisterDelphiFunction(@GetSensorValues, 'GetSensorValues', cdRegister);
    RegisterDelphiFunction(@SetSensorVin, 'SetSensorVin', cdRegister);
    RegisterDelphiFunction(@SetAxisSpeedRef, 'SetAxisSpeedRef', cdRegister);
    RegisterDelphiFunction(@SetMotorControllerState, 'SetMotorControllerState', cdRegister);
    RegisterDelphiFunction(@SetMotorControllerPars, 'SetMotorControllerPars', cdRegister);
    RegisterDelphiFunction(@SetRobotPos, 'SetRobotPos', cdRegister);
  end;
end;

procedure TRafImport_PathFinder.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_PathFinder(CompExec.Comp);
end;

procedure TRafImport_user_charts.CompileImport1(CompExec: TPSScript);
begin
  SIRegister_user_charts(CompExec.Comp);
end;

procedure AddSimTwoPlugins(Script: TPSScript; Owner: TComponent);

  procedure Add(P: TPSPlugin);
  begin
    TPSPluginItem(Script.Plugins.Add).Plugin := P;
  end;

begin
  // Editor.lfm's Plugins list first, then TFEditor.FormCreate's four
  Add(TRafImport_Classes.Create(Owner));
  Add(TRafImport_Controls.Create(Owner));
  Add(TRafImport_StdCtrls.Create(Owner));
  Add(TRafImport_Forms.Create(Owner));
  Add(TRafImport_dynmatrix.Create(Owner));
  Add(TRafImport_ODERobotsPublished.Create(Owner));
  Add(TRafImport_PathFinder.Create(Owner));
  Add(TRafImport_user_charts.Create(Owner));
end;

end.
