#include "stages/ingest/ingest_stage.hpp"

int main(int argc, char** argv)
{
    return tigerlod::run_stage<tigerlod::ingest::IngestStage>(argc, argv);
}
