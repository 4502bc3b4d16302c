#pragma once
// Entry points of the catpaq subcommands (argv[0] is the subcommand name).
namespace catpaq {

int cmd_info(int argc, char** argv);
int cmd_convert(int argc, char** argv);
int cmd_verify(int argc, char** argv);
int cmd_serve(int argc, char** argv);
int cmd_render(int argc, char** argv);
int cmd_view(int argc, char** argv);

}  // namespace catpaq
