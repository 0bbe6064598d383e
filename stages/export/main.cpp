#include "stages/export/export_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::exporter::ExportStage>(argc, argv);
}
