{ robotatfactory: a Linux stand-in for the Win32 `ShellAPI` unit. SceneEdit.pas uses SHFileOperation only in
  its "new scene" menu (copying a scene folder); here it reports failure, so that menu does nothing on
  Linux. Found through platform/$(TargetOS) in SimTwo.lpi's search path, as Windows.pas. }
unit ShellAPI;

{$mode delphi}

interface

type
  TSHFileOpStruct = record
    Wnd: PtrUInt;
    wFunc: LongWord;
    pFrom: PChar;
    pTo: PChar;
    fFlags: Word;
    fAnyOperationsAborted: LongBool;
    hNameMappings: Pointer;
    lpszProgressTitle: PChar;
  end;
  SHFILEOPSTRUCT = TSHFileOpStruct;

const
  FO_COPY = 2;
  FOF_SILENT = $4;
  FOF_NOCONFIRMATION = $10;

function SHFileOperation(var lpFileOp: TSHFileOpStruct): Integer;

implementation

function SHFileOperation(var lpFileOp: TSHFileOpStruct): Integer;
begin
  Result := 1; // not supported on Linux
end;

end.
